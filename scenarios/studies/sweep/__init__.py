"""Parameter sweeps: specification, execution (pool, Dask, batched), storage, rows and plots."""
