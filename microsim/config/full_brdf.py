"""The incidences of a full-BRDF run (``illumination.incidences = N``, conventions §4).

A table read as a BRDF at any pair of directions (:mod:`microsim.models.tabulated`) needs incidences
over the whole hemisphere: its interpolation is linear in cos theta_i, and a table is taken for
a full BRDF only where its incidences leave no gap in cos theta_i wider than MAX_COS_GAP (from
normal incidence to the first, between two, and from the last to the horizon). N incidences are
put at the centres of N of the sensor's rings, each where a ring of cells lies (so that a cell
and its reciprocal, wi and wo exchanged, are both read at a table incidence), from the polar cap
(normal incidence) to the last ring (near grazing); the rings between are those that make the
widest gap in cos theta_i the smallest the rings allow, and, among those, the gaps the most even
(the least sum of their squares): :func:`ring_choice`. A run whose N cannot meet MAX_COS_GAP at
its sensor is refused before it traces (:func:`expand`), naming the least N that can. For an
anisotropic scene, ``illumination.azimuths = M`` traces each polar angle but the normal at M
azimuths 360 j / M.
"""

from __future__ import annotations

import numpy as np

from microsim.tracer.sensor import Sensor

#: the most incidences a run traces (illumination.theta_i_deg's longest list)
MAX_INCIDENCES = 256
#: the largest polar angle of an incidence (illumination.theta_i_deg's bound): the last ring's
#: centre of a sensor of more than about 600 000 cells lies beyond it, and is held there
MAX_THETA_DEG = 89.9


#: the widest gap in cos(theta_i) a table's incidences may leave (between two, and from the
#: first to normal incidence and the last to the horizon) to be taken for a full BRDF
MAX_COS_GAP = 0.25


def widest_gap(cosines) -> tuple[float, float]:
    """(the widest gap between incidences of cosines ``cosines``, the ends 1 and 0 included; the
    cosine it starts from)."""
    nodes = np.concatenate([[1.0], np.sort(np.asarray(cosines, float))[::-1], [0.0]])
    gap = -np.diff(nodes)
    k = int(np.argmax(gap))
    return float(gap[k]), float(nodes[k])


def ring_choice(cosines: np.ndarray, incidences: int) -> tuple[np.ndarray, np.ndarray]:
    """(the rings of ``incidences`` incidences, increasing; the widest gap the best choice of
    n + 1 rings leaves, for every n + 1 from 1 to the rings) among rings of centre cosines
    ``cosines`` (decreasing, the first the pole's): the first and the last ring, and between them
    those whose widest gap in cosine is the least, then whose sum of squared gaps is (two exact
    dynamic programmes over the rings)."""
    c = np.asarray(cosines, float)
    rings = c.size
    step = c[:, None] - c[None, :]  # step[i, j]: the gap from ring i to a later ring j
    later = np.triu(np.ones((rings, rings), bool), 1)
    # widest[k, j]: the least widest gap of k + 1 rings from the first to ring j
    widest = np.full((rings, rings), np.inf)
    widest[0, 0] = 0.0
    for k in range(1, rings):
        widest[k] = np.min(np.where(later, np.maximum(widest[k - 1][:, None], step), np.inf), axis=0)
    last_gap = c[-1]  # from the last ring to the horizon
    best = np.maximum(widest[:, -1], last_gap)
    if incidences == 1:
        return np.zeros(1, int), best
    allowed = later & (step <= best[incidences - 1] * (1 + 1e-12))
    squares = np.full((incidences, rings), np.inf)
    squares[0, 0] = 0.0
    came = np.zeros((incidences, rings), int)
    for k in range(1, incidences):
        total = np.where(allowed, squares[k - 1][:, None] + step ** 2, np.inf)
        came[k] = np.argmin(total, axis=0)
        squares[k] = total[came[k], np.arange(rings)]
    chosen = [rings - 1]
    for k in range(incidences - 1, 0, -1):
        chosen.append(int(came[k, chosen[-1]]))
    return np.array(chosen[::-1]), best


def polar_angles_deg(incidences: int, cells: int) -> list[float]:
    """The polar angles of ``incidences`` incidences for a sensor of ``cells`` cells (module doc),
    degrees; ValueError (one line) if it has fewer rings than that, or if they cannot keep the
    gaps within MAX_COS_GAP."""
    centres = Sensor.build(cells).ring_centres()
    if incidences > centres.size:
        raise ValueError(f"illumination.incidences = {incidences}: more than the {centres.size} rings of sensor.cells "
                         f"= {cells} (one incidence a ring); accepted: 2 to {centres.size}, or more sensor.cells")
    rings, best = ring_choice(np.cos(centres), incidences)
    if best[incidences - 1] > MAX_COS_GAP:
        enough = np.flatnonzero(best <= MAX_COS_GAP)
        accepted = (f"{enough[0] + 1} to {centres.size}" if enough.size else
                    "none at these cells: more sensor.cells")
        raise ValueError(f"illumination.incidences = {incidences}: at sensor.cells = {cells} they leave a gap of "
                         f"{best[incidences - 1]:.3g} in cos theta_i, wider than a full BRDF's {MAX_COS_GAP:g}; "
                         f"accepted: {accepted}")
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
