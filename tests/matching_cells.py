"""Matching sensor cells for reciprocity checks: incidences at ring centres, azimuths 0 and 90 deg."""

from fractions import Fraction

import numpy as np

from microsim.tracer.sensor import Sensor

#: a sensor whose rings below have cell counts divisible by 4 (12, 24, 44, 52, 60 cells): each has
#: cells centred at azimuths 0 and 90 deg, where the incidences are
RECIPROCITY_CELLS = 675
RINGS = (2, 4, 8, 10, 13)


def ring_incidences():
    """(ring, theta_i in degrees, phi_i in degrees) at the centres of RINGS, phi_i 0 and 90 deg."""
    theta = np.degrees(Sensor.build(RECIPROCITY_CELLS).ring_centres()[list(RINGS)])
    return [(ring, t, phi) for ring, t in zip(RINGS, theta) for phi in (0.0, 90.0)]


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
