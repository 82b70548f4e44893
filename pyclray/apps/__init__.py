"""The applications on top of the product: the command line (cli/, one module per command) and the
Dask cluster (cluster.py)."""
