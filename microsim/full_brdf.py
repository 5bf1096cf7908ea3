"""The incidences of a full-BRDF run (``illumination.incidences = N``, conventions §4).

A table read as a BRDF at any pair of directions (:mod:`microsim.tabulated`) needs incidences
over the whole hemisphere. N of them are put at the centres of N of the sensor's rings, as evenly
as whole rings allow, from the polar cap (normal incidence) to the last ring (near grazing): the
sensor's rings are nearly equal in theta, so the incidences are evenly spaced where N - 1 divides
the rings less one (their spacings differ by one ring at most otherwise), and each lies where a
ring of cells does, so that a cell and its reciprocal (wi and wo exchanged) are both read at a
table incidence. For
an anisotropic scene, ``illumination.azimuths = M`` traces each polar angle but the normal at M
azimuths 360 j / M.
"""

from __future__ import annotations

import numpy as np

from .sensor import Sensor

#: the most incidences a run traces (illumination.theta_i_deg's longest list)
MAX_INCIDENCES = 256
#: the largest polar angle of an incidence (illumination.theta_i_deg's bound): the last ring's
#: centre of a sensor of more than about 600 000 cells lies beyond it, and is held there
MAX_THETA_DEG = 89.9


def polar_angles_deg(incidences: int, cells: int) -> list[float]:
    """The polar angles of ``incidences`` incidences for a sensor of ``cells`` cells (module doc),
    degrees; ValueError (one line) if it has fewer rings than that."""
    centres = Sensor.build(cells).ring_centres()
    if incidences > centres.size:
        raise ValueError(f"illumination.incidences = {incidences}: more than the {centres.size} rings of sensor.cells "
                         f"= {cells} (one incidence a ring); accepted: 2 to {centres.size}, or more sensor.cells")
    rings = np.round(np.linspace(0, centres.size - 1, incidences)).astype(int)
    return [min(float(d), MAX_THETA_DEG) for d in np.degrees(centres[rings])]


def incidences_deg(incidences: int, azimuths: int, cells: int) -> tuple[list[float], list[float]]:
    """(theta_i_deg, phi_i_deg) of a full-BRDF run: each polar angle of :func:`polar_angles_deg` at
    ``azimuths`` azimuths, the normal incidence once."""
    thetas, phis = [], []
    for theta in polar_angles_deg(incidences, cells):
        for j in range(1 if theta == 0.0 else azimuths):
            thetas.append(theta)
            phis.append(360.0 * j / azimuths)
    if len(thetas) > MAX_INCIDENCES:
        raise ValueError(f"illumination.azimuths = {azimuths}: {len(thetas)} incidences with illumination.incidences = "
                         f"{incidences}; accepted: at most {MAX_INCIDENCES} incidences in all")
    return thetas, phis


def expand(data, default_cells: int):
    """The config dictionary ``data`` with ``illumination.theta_i_deg`` and ``phi_i_deg`` made from
    ``illumination.incidences`` and ``azimuths`` (a config that names them both must give the
    same angles: a table's stored config does); left as it is if it has no ``incidences``.
    ValueError (one line) for a config that cannot be expanded; ``default_cells``: sensor.cells
    where the config does not give it."""
    illumination = data.get("illumination") if isinstance(data, dict) else None
    if not isinstance(illumination, dict) or "incidences" not in illumination:
        if isinstance(illumination, dict) and "azimuths" in illumination:
            raise ValueError("illumination.azimuths: only with illumination.incidences (a full BRDF); give "
                             "phi_i_deg for the azimuths of theta_i_deg")
        return data
    n, m = illumination["incidences"], illumination.get("azimuths")
    m = 1 if m is None else m
    sensor = data.get("sensor", {})
    cells = sensor.get("cells", default_cells) if isinstance(sensor, dict) else default_cells
    for key, value, least in (("incidences", n, 2), ("azimuths", m, 1)):
        if not isinstance(value, int) or isinstance(value, bool) or value < least:
            raise ValueError(f"illumination.{key} = {value!r}: accepted: a whole number, at least {least}"
                             + (" and at most the sensor's rings" if key == "incidences" else ""))
    if not isinstance(cells, int) or isinstance(cells, bool) or cells < 1:
        return data  # the schema names sensor.cells and its range
    thetas, phis = incidences_deg(n, m, cells)
    given = illumination.get("theta_i_deg"), illumination.get("phi_i_deg")
    if given != (None, None) and not _same(given, (thetas, phis)):
        raise ValueError(f"illumination.theta_i_deg: given with illumination.incidences = {n}, which chooses the "
                         "incidences itself; accepted: one of theta_i_deg (and phi_i_deg) or incidences")
    return {**data, "illumination": {**illumination, "theta_i_deg": thetas, "phi_i_deg": phis}}


def _same(given, made) -> bool:
    """Whether the angles ``given`` in a config are those :func:`incidences_deg` made."""
    try:
        return all(np.allclose(np.broadcast_to(np.asarray(g, float), len(m)), m, rtol=0, atol=1e-9)
                   for g, m in zip(given, made))
    except (TypeError, ValueError):
        return False
