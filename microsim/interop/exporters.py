"""A full-BRDF table in the formats other tools read (``microsim export``).

Both formats hold isotropic BRDFs on a regular grid of their own, every node filled from the
table's tabulated BRDF (:class:`microsim.models.tabulated.TabulatedBRDF`): an anisotropic table (incidences
at several azimuths) is refused.

- **MERL** (``merl``): the binary layout of the MERL BRDF database (Matusik et al. 2003), read by
  BRDF Explorer, pbrt-v2 and many fitting tools: three int32 (90, 90, 180), then three channels
  (red, green, blue) of 90 x 90 x 180 float64, little-endian, over the half-angle theta_h
  (bin i: sqrt(theta_h / (pi / 2)) 90 in [i, i + 1)), the difference angle theta_d (uniform) and
  the difference azimuth phi_d in [0, pi) (uniform; phi_d and phi_d + pi are one by
  reciprocity), phi_d fastest. A channel holds f / scale, scales 1/1500, 1.15/1500 and 1.66/1500
  (a reader multiplies them back). Each bin holds f at its centre in index space; bins whose
  centre lies below the horizon hold 0. The three channels hold the same BRDF (microsim is grey).
- **netCDF grid** (``netcdf-grid``): Eradiate's ``mqdiffuse`` layout, a variable
  ``brdf(cos_theta_o, phi_d, cos_theta_i)`` in 1/sr on evenly spaced coordinates, cosines
  from 0 to 1 (``dimensionless``), phi_d = phi_o - phi_i from 0 to 2 pi without the end (``rad``;
  0 is the backscatter half plane, conventions §1). The horizon's nodes (a cosine of 0) hold the
  limit from above (the BRDF at a cosine of HORIZON).

Files are written under a temporary name and renamed when complete.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from microsim import __version__
from microsim.core.files import atomic
from microsim.core.frames import direction
from microsim.tables import netcdf

#: MERL's bins: theta_h, theta_d, phi_d
MERL_BINS = (90, 90, 180)
#: what a MERL channel's stored numbers are multiplied by (red, green, blue)
MERL_SCALES = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
#: the netCDF grid's nodes: cos_theta_o, phi_d, cos_theta_i
GRID_NODES = (91, 144, 91)
#: the cosine the horizon's nodes of the netCDF grid are read at
HORIZON = 1e-6
#: format -> the suffix of its default file name
SUFFIXES = {"merl": ".binary", "netcdf-grid": ".nc"}


def export(tabulated, fmt: str, out: Path) -> Path:
    """Write ``tabulated`` (a :class:`~microsim.models.tabulated.TabulatedBRDF`) in format ``fmt`` to
    ``out``, atomically; ValueError (one line) for a table that is not a full BRDF, or anisotropic."""
    tabulated.require_full_brdf()
    if tabulated.grid.anisotropic:
        raise ValueError(f"--format {fmt}: {tabulated.path} is anisotropic (incidences at {tabulated.grid.phi.size} "
                         "azimuths); the format holds isotropic BRDFs (f of theta_i, theta_o and phi_o - phi_i)")
    with atomic(out) as tmp:
        WRITERS[fmt](tabulated, tmp)
    return out


def merl_bin_centres() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(theta_h, theta_d, phi_d) of every MERL bin's centre in index space, each (90, 90, 180)."""
    n_h, n_d, n_p = MERL_BINS
    theta_h = ((np.arange(n_h) + 0.5) / n_h) ** 2 * (np.pi / 2)
    theta_d = (np.arange(n_d) + 0.5) / n_d * (np.pi / 2)
    phi_d = (np.arange(n_p) + 0.5) / n_p * np.pi
    return np.meshgrid(theta_h, theta_d, phi_d, indexing="ij")


def half_difference_directions(theta_h, theta_d, phi_d) -> tuple[np.ndarray, np.ndarray]:
    """(w_in, w_out), each (..., 3), of half-difference angles (Rusinkiewicz 1998) with the half
    vector's azimuth 0: w_in is the difference vector turned by theta_h about y, w_out its
    mirror image about the half vector."""
    d = direction(theta_d, phi_d)
    c, s = np.cos(theta_h)[..., None], np.sin(theta_h)[..., None]
    w_in = np.concatenate([c * d[..., :1] + s * d[..., 2:], d[..., 1:2], -s * d[..., :1] + c * d[..., 2:]], axis=-1)
    half = np.concatenate([s, np.zeros_like(s), c], axis=-1)
    w_out = 2.0 * np.sum(w_in * half, axis=-1, keepdims=True) * half - w_in
    return w_in, w_out


def write_merl(tabulated, path: Path) -> None:
    """The MERL binary of ``tabulated`` (module doc)."""
    w_in, w_out = half_difference_directions(*merl_bin_centres())
    f = tabulated(w_in.reshape(-1, 3), w_out.reshape(-1, 3))
    with open(path, "wb") as out:
        np.asarray(MERL_BINS, "<i4").tofile(out)
        for scale in MERL_SCALES:
            (f / scale).astype("<f8").tofile(out)


def grid_coordinates() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The netCDF grid's coordinates: cos_theta_o, phi_d, cos_theta_i (module doc)."""
    n_o, n_p, n_i = GRID_NODES
    return np.linspace(0.0, 1.0, n_o), np.linspace(0.0, 2 * np.pi, n_p, endpoint=False), np.linspace(0.0, 1.0, n_i)


def write_netcdf_grid(tabulated, path: Path) -> None:
    """The regular grid of ``tabulated`` in Eradiate's mqdiffuse layout (module doc), a netCDF-4 file."""
    cos_o, phi_d, cos_i = grid_coordinates()
    mu_o, phi, mu_i = np.meshgrid(np.maximum(cos_o, HORIZON), phi_d, np.maximum(cos_i, HORIZON), indexing="ij")
    wo = direction(np.arccos(mu_o), phi)
    wi = direction(np.arccos(mu_i), np.zeros_like(mu_i))
    brdf = tabulated(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(mu_o.shape)
    with h5py.File(path, "w", libver=("v110", "v110")) as h5:
        scales = []
        for name, values, unit, long_name in (
                ("cos_theta_o", cos_o, "dimensionless", "cosine of the outgoing zenith angle"),
                ("phi_d", phi_d, "rad", "azimuth difference phi_o - phi_i (0: the backscatter half plane)"),
                ("cos_theta_i", cos_i, "dimensionless", "cosine of the incoming zenith angle")):
            scale = netcdf.dimension(h5, name, values)
            scale.attrs["units"], scale.attrs["long_name"] = unit, long_name
            scales.append(scale)
        variable = h5.create_dataset("brdf", data=brdf)
        netcdf.attach(variable, scales)
        variable.attrs["units"] = "1/sr"
        variable.attrs["long_name"] = "bidirectional reflectance distribution function"
        h5.attrs["title"] = "microsim full BRDF, Eradiate mqdiffuse layout"
        h5.attrs["source"] = f"microsim {__version__}, from the table {tabulated.path}"
        h5.attrs["interpolation"] = ("microsim.models.tabulated: linear in cos theta_i between the table's incidences "
                                     "and between its cells' centres, made reciprocal")


WRITERS = {"merl": write_merl, "netcdf-grid": write_netcdf_grid}
