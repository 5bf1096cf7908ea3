"""microsim: ground-truth BRDF tables from explicit random microgeometry."""

from . import inlining, kernel_cache

__version__ = "0.1.0"

kernel_cache.install()
inlining.install()
