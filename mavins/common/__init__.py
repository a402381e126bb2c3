"""What the rooms above the core share: the contract's files, parse-time option checks, the progress
bar, and the one way to run many jobs (local processes or a Dask cluster)."""
