"""microsim: ground-truth BRDF tables from explicit random microgeometry."""

__version__ = "0.1.0"
