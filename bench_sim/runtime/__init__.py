"""Runtime underneath the pipeline: the Mitsuba/Dr.Jit backend, threads and random streams,
the Dask execution layer, resource checks and provenance."""
