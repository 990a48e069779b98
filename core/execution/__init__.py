"""Who bakes the tiles: threads, worker processes, a Dask cluster; what a bake costs."""
