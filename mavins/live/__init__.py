"""The live shell every command face shares: message -> ingest -> engine (the strapdown kernel and the
filter's live side) -> solution; the IMU set of --imus."""
