"""One run's slot log: MCAP, one JSON message per slot, written, read back and turned into
tables."""
