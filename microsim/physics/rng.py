"""Counter-based random streams for the tracer (numba).

Every path owns a 64-bit state derived from (seed, realization, incidence, path): the
numbers a path draws do not depend on how work is split between processes or
workers, which makes tables bit-identical for any ``--workers``. The generator is SplitMix64
(Steele, Lea & Flood 2014): a Weyl sequence with a strong 64-bit finaliser.
"""

import numba
import numpy as np

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2^-53


@numba.njit(cache=True, error_model="numpy", inline="always")
def mix64(z):
    """SplitMix64 finaliser: a bijective avalanche of a uint64."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@numba.njit(cache=True, error_model="numpy")
def stream_key(seed, realization, incidence):
    """Key of the stream of one (seed, realization, incidence) unit of work."""
    k = mix64(np.uint64(seed) + _GAMMA)
    k = mix64(k ^ (np.uint64(realization) * _M2 + _GAMMA))
    return mix64(k ^ (np.uint64(incidence) * _M1 + _GAMMA))


@numba.njit(cache=True, error_model="numpy", inline="always")
def path_state(key, path):
    """Initial state of path number ``path`` of the stream ``key``."""
    return mix64(key ^ mix64(np.uint64(path) + _GAMMA))


@numba.njit(cache=True, error_model="numpy", inline="always")
def uniform(states, i):
    """Next uniform double in [0, 1) of path ``i``; advances ``states[i]``."""
    s = states[i] + _GAMMA
    states[i] = s
    return np.float64(mix64(s) >> _S11) * _INV53


def geometry_rng(seed: int, realization: int) -> np.random.Generator:
    """The numpy generator of one geometry realization (independent of the path streams)."""
    return np.random.default_rng(np.random.SeedSequence([seed, realization, 0x6E0]))
