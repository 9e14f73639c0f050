"""Experiments: grids of cells, sweeps over paired seeds, sweep folders that resume, where
chunks run (this process, Dask, a GPU), summaries and the runs worth watching."""
