"""How microsim's kernels are compiled and cached: numba's setup, the on-disk cache and its stamp,
inlining, compile timing, kernels dispatched by record type, and the forkserver's preload."""
