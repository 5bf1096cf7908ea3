"""A run planned and traced: the plan and its reduction to estimates, the executors that trace
units of it (local processes, Dask), and the unit store that makes it resumable."""
