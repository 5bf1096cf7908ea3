"""Reciprocity of a traced table, and the power of the check.

Contract: incidences sit at the centres of sensor rings (:func:`ring_incidences`), so that the
cell of ring b at azimuth phi_b seen from incidence a, and the cell of ring a at phi_a seen from
incidence b, estimate the same BRDF value f(a -> b) = f(b -> a) up to the averaging over a cell.
:func:`reciprocity_z` gives |f(a -> b) - f(b -> a)| over the combined standard error of every
pair; a reciprocal table keeps them within the bounds of a Student-t z (the tests take max z
<= 4.5, or the mean z^2 within :func:`microsim.testing.bounds.chi2_bound`). The power of the
check: :func:`non_reciprocal_z` is the same comparison of f cos(theta_o), which is not
reciprocal, and a check that passes must reject it. :func:`azimuth_matched_z` pairs every
cell of equal azimuth of incidences at phi_i = 0 (for scenes isotropic in azimuth).
"""

from fractions import Fraction

import numpy as np

from microsim.tracer.sensor import Sensor

#: a sensor whose rings below have cell counts divisible by 4 (12, 24, 44, 52, 60 cells): each has
#: cells centred at azimuths 0 and 90 deg, where the incidences are
RECIPROCITY_CELLS = 675
RINGS = (2, 4, 8, 10, 13)


def ring_incidences(cells: int = RECIPROCITY_CELLS, rings=RINGS):
    """(ring, theta_i in degrees, phi_i in degrees) at the centres of ``rings`` of the sensor of
    ``cells`` cells, phi_i 0 and 90 deg (each ring's cell count divisible by 4: it has cells centred
    at both)."""
    sensor = Sensor.build(cells)
    assert all(int(sensor.ring_counts[ring]) % 4 == 0 for ring in rings), "a ring's cells miss 0 or 90 deg"
    theta = np.degrees(sensor.ring_centres()[list(rings)])
    return [(ring, t, phi) for ring, t in zip(rings, theta) for phi in (0.0, 90.0)]


def ring_illumination(incidences) -> dict:
    """The ``[illumination]`` section of :func:`ring_incidences`' incidences."""
    return {"theta_i_deg": [float(t) for _, t, _ in incidences], "phi_i_deg": [float(p) for _, _, p in incidences]}


def reciprocity_z(table, incidences, value, stderr):
    """|value(a -> b) - value(b -> a)| / combined standard error, for every pair of incidences a < b
    (the cell of b's ring at b's azimuth seen from a, and the reverse)."""
    sensor = table.sensor

    def cell_at(ring, phi):
        j = Fraction(phi / 360.0) * int(sensor.ring_counts[ring])
        assert j.denominator == 1
        return sensor.ring_start[ring] + int(j)

    z = []
    for a, (ring_a, _, phi_a) in enumerate(incidences):
        for b, (ring_b, _, phi_b) in enumerate(incidences[a + 1:], start=a + 1):
            forward, backward = (a, cell_at(ring_b, phi_b)), (b, cell_at(ring_a, phi_a))
            z.append(abs(value[forward] - value[backward]) / np.hypot(stderr[forward], stderr[backward]))
    return np.array(z)


def cell_cosines(sensor) -> np.ndarray:
    """cos(theta_o) at the polar middle of every cell of ``sensor``."""
    t_lo, t_hi = sensor.cell_bounds()[:2]
    return np.cos(0.5 * (t_lo + t_hi))


def non_reciprocal_z(table, incidences):
    """:func:`reciprocity_z` of f cos(theta_o), which is not reciprocal: the check's power."""
    mu = cell_cosines(table.sensor)
    return reciprocity_z(table, incidences, table.brdf * mu, table.brdf_stderr * mu)


def matched_cells(sensor, ring_a, ring_b):
    """Pairs (cell of ring b, cell of ring a) whose centres have the same azimuth."""
    na, nb = int(sensor.ring_counts[ring_a]), int(sensor.ring_counts[ring_b])
    by_azimuth = {Fraction(j, na): sensor.ring_start[ring_a] + j for j in range(na)}
    return [(sensor.ring_start[ring_b] + j, by_azimuth[Fraction(j, nb)])
            for j in range(nb) if Fraction(j, nb) in by_azimuth]


def reciprocal_pairs(sensor, rings):
    """(incidence a, cell at ring b, incidence b, cell at ring a) at equal relative azimuth, a < b,
    for incidences at the centres of ``rings`` (phi_i = 0)."""
    for ia, ring_a in enumerate(rings):
        for ib, ring_b in enumerate(rings):
            if ib > ia:
                for cell_b, cell_a in matched_cells(sensor, ring_a, ring_b):
                    yield ia, cell_b, ib, cell_a


def azimuth_matched_z(value, stderr, sensor, rings) -> np.ndarray:
    """|value(a -> b) - value(b -> a)| over its combined standard error, for every pair of cells of
    equal azimuth of incidences at the centres of ``rings``, phi_i = 0 (a scene isotropic in azimuth)."""
    return np.array([abs(value[ia, cb] - value[ib, ca]) / np.hypot(stderr[ia, cb], stderr[ib, ca])
                     for ia, cb, ib, ca in reciprocal_pairs(sensor, rings)])
