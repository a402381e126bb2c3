"""The Rerun side: the recorder (with its blueprint) and headless review of recordings."""
