"""The path tracer: the sensor, the scene and its shapes, materials, the integrators' kernels, the
estimators that tally them, the Embree binding, and the numba plumbing under :mod:`microsim.tracer.jit`.
It imports only :mod:`microsim.core` and :mod:`microsim.physics`."""
