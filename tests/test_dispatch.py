"""Kernels chosen by a record's type (microsim.tracer.jit.dispatch): the implementation of the record's
class is the one called, and a write it makes is seen by the code after it.

numba 0.68's ``overload(inline="always")`` loses that write when an inlined function with an
early return follows (docs/developer/performance.md): Generic compiles implementations as calls instead.
"""

from typing import NamedTuple

import numba
import numpy as np

from microsim.tracer.jit.dispatch import Generic


class Doubling(NamedTuple):
    weight: np.ndarray


class Halving(NamedTuple):
    weight: np.ndarray


def begin(record, i):
    """Set the weight of row i, and return the factor of the record's kind."""


BEGIN = Generic(begin)


@BEGIN.register(Doubling)
@numba.njit
def _begin_doubling(record, i):
    record.weight[i] = 1.0
    return 2.0


@BEGIN.register(Halving)
@numba.njit
def _begin_halving(record, i):
    record.weight[i] = 1.0
    return 0.5


@numba.njit(inline="always")
def scale(record, i, factor, stop):
    if stop:
        return False
    record.weight[i] = record.weight[i] * factor
    return True


@numba.njit
def begin_then_scale(record):
    factor = begin(record, 0)
    scale(record, 0, factor, False)
    return record.weight[0]


def test_each_record_class_gets_its_own_implementation_and_its_writes_are_kept():
    assert begin_then_scale(Doubling(np.zeros(1))) == 2.0
    assert begin_then_scale(Halving(np.zeros(1))) == 0.5
