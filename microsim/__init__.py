"""microsim: ground-truth BRDF tables from explicit random microgeometry."""

from microsim.tracer.jit import numba_setup

__version__ = "0.1.0"

numba_setup.install_when_numba_loads()
