"""Layer 7, runtime: where batches run (worker processes, a Dask cluster) and the process settings
they need."""
