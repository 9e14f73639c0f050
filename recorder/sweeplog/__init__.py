"""A sweep's files: the sweep log (MCAP), its Rerun recording and ``results.parquet``."""
