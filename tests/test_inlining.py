"""numba's inliner copies a callee's blocks with one copy of its scope (microsim/tracer/jit/inlining.py)."""

import copy

import numba
from numba.core import compiler, inline_closurecall

from microsim.tracer.jit import inlining


def branchy(x):
    total = 0.0
    for k in range(3):
        if x > k:
            total += x * k
        else:
            total -= k
    return total


def test_the_inliner_is_wrapped_once():
    assert inline_closurecall.InlineWorker.inline_ir.shares_scope_copies
    wrapped = inline_closurecall.InlineWorker.inline_ir
    inlining.install()
    assert inline_closurecall.InlineWorker.inline_ir is wrapped


def test_the_blocks_of_one_scope_share_one_copy_of_it():
    blocks = compiler.run_frontend(branchy).blocks
    assert len(blocks) > 3
    (scope,) = {id(block.scope): block.scope for block in blocks.values()}.values()
    copies = inlining.SharedScopeCopy()
    copied = [copies.deepcopy(block) for block in blocks.values()]
    assert len({id(block.scope) for block in copied}) == 1
    assert copied[0].scope is not scope
    assert set(copied[0].scope.localvars._con) == set(scope.localvars._con)
    one_by_one = [copy.deepcopy(block) for block in blocks.values()]  # numba's own way: a scope each
    assert len({id(block.scope) for block in one_by_one}) == len(blocks)


@numba.njit(inline="always")
def _leaf(x):
    return branchy_kernel(x) + 1.0


branchy_kernel = numba.njit(inline="always")(branchy)


@numba.njit(inline="always")
def _middle(x):
    return _leaf(x) * _leaf(x + 1.0)


@numba.njit
def _outer(x):
    return _middle(x) - _middle(-x)


def test_kernels_inlined_into_kernels_they_inline_compute_what_python_does():
    for x in (-2.0, 0.5, 1.5, 4.0):
        leaf = lambda v: branchy(v) + 1.0  # noqa: E731
        middle = lambda v: leaf(v) * leaf(v + 1.0)  # noqa: E731
        assert _outer(x) == middle(x) - middle(-x)
