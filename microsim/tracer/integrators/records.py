"""Named records of the tracer's state: structure-of-arrays bundles that numba kernels take.

As pbrt-v4's wavefront work items and MCDC's records do, each bundle is a namedtuple of arrays
(numba compiles a field access to a struct member, and can cache the kernels that take them
because the classes live in this importable module). Kernels take a few bundles and a row
index instead of dozens of arrays. A new per-path field is one entry of ``PATH_FIELDS``: it is
allocated with the others and, on the embreex backend, carried along when live paths are
compacted (:func:`microsim.tracer.integrators.events.move_path`); no kernel signature changes. Its
starting value is set where a path starts (``events.begin_path``), its updates where it
changes. What paths produce is a :class:`microsim.core.tally.Tally`.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from microsim.core.tally import SINGLE_ALBEDO

#: what a path carries from segment to segment: name -> dtype (one row per path)
PATH_FIELDS = {
    "weight": np.float64,
    "order": np.int32,  # interactions so far
    "idle": np.int32,  # segments since the last interaction (side wraps, pass-throughs)
    "rng": np.uint64,  # state of the path's random stream (microsim.physics.rng)
    "from_base": np.int8,  # 1 if the first interaction was with the scene's base plane
}
Paths = namedtuple("Paths", PATH_FIELDS)

#: the segment each live path traces next, in float32 as Embree takes it: origin and direction
#: (n, 3), the distance ``tfar`` to the end of the segment, and which boundary ends it (``end``)
Rays = namedtuple("Rays", ["origin", "direction", "tfar", "end"])

#: the paths of one unit of work: incidence direction wi (float64 (3,)), random stream key
#: (uint64), number of paths, max_order (0: unlimited), and the albedo scales c_j / c_max of a
#: run of several albedos (float64 (A,); SINGLE_ALBEDO otherwise; see :class:`microsim.core.tally.Tally`)
Beam = namedtuple("Beam", ["wi", "key", "n_paths", "max_order", "albedo_scale"], defaults=(SINGLE_ALBEDO,))


def allocate_paths(n: int) -> Paths:
    return Paths(*(np.empty(n, dtype) for dtype in PATH_FIELDS.values()))


def allocate_rays(n: int) -> Rays:
    return Rays(np.empty((n, 3), np.float32), np.empty((n, 3), np.float32), np.empty(n, np.float32),
                np.empty(n, np.int8))
