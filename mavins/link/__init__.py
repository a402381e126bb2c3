"""The MAVLink boundary: links, signing, ingest of IMU messages, publishing of solutions."""
