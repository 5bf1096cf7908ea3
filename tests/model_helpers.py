"""Helpers shared by the analytic-model tests (tests/test_models_*.py)."""

import math

import numpy as np
import pytest

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
    with pytest.raises(ValueError) as err:
        models.create(name, **params)
    for key in keys:
        assert key in str(err.value)


def assert_zero_below_horizon(model, above, below):
    """f = 0 when either direction is below the horizon, both ways round (conventions §8)."""
    assert model(below, above) == 0.0 and model(above, below) == 0.0
