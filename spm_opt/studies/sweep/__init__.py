"""Parameter sweeps: specifications, tasks, runners (process pool or Dask), results."""
