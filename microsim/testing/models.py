"""What the analytic-model tests share (tests/test_models_*.py).

Contract: :func:`random_pairs` draws direction pairs of a fixed seed above the horizon;
:func:`assert_rejected` asserts that a model refuses parameters with a ValueError naming every
key given (conventions §9); :func:`assert_zero_below_horizon` that f = 0 when either direction is
below the horizon (conventions §8).
"""

import math

import numpy as np

from microsim import models
from microsim.core.frames import direction


def random_pairs(n, seed, top=89.9):
    """n pairs (wi, wo): polar angles uniform in [0, top] degrees, azimuths uniform."""
    rng = np.random.default_rng(seed)
    wi = direction(np.radians(rng.uniform(0, top, n)), rng.uniform(0, 2 * math.pi, n))
    wo = direction(np.radians(rng.uniform(0, top, n)), rng.uniform(0, 2 * math.pi, n))
    return wi, wo


def assert_rejected(name, params, keys):
    """``models.create(name, **params)`` raises ValueError naming every key (conventions §9)."""
    try:
        models.create(name, **params)
    except ValueError as err:
        assert all(key in str(err) for key in keys), (keys, str(err))
    else:
        raise AssertionError(f"models.create({name!r}, **{params!r}) raised no ValueError")


def assert_zero_below_horizon(model, above, below):
    """f = 0 when either direction is below the horizon, both ways round (conventions §8)."""
    assert model(below, above) == 0.0 and model(above, below) == 0.0
