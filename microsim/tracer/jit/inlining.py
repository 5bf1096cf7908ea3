"""numba's ``inline="always"`` without its quadratic copies of the callee's IR (numba issue #8989).

To inline a callee, numba deep-copies its IR block by block, each block with a fresh memo: every
block's copy takes a copy of the function's whole scope (all its variables), and the copied
blocks then hold as many scopes, which numba compares with each other. The cost is blocks x
variables per inlining, and the tracers inline kernels that inline others: without this module,
compiling the direct backend's kernel for native spheres spends most of its time in
``copy.deepcopy``.

:func:`install` wraps ``InlineWorker.inline_ir`` so that, within one inlining, the blocks of one
scope are copied with one memo: one copy of the scope, shared by the copied blocks as the
originals share theirs, and every other object copied as numba copies it. The machine code is
the same (the assembly of the three tracers' kernels, identical with and without it); only the
compile is shorter (measurements: docs/developer/performance.md, sections 'Inlining without
quadratic IR copies' and 'Compile times').
"""

from __future__ import annotations

import copy

from numba.core import inline_closurecall, ir


class SharedScopeCopy:
    """The ``copy`` module as numba's inliner calls it, except that ``deepcopy(block)`` copies
    the blocks of one scope with one memo (one per scope for the life of this object)."""

    def __init__(self):
        self.memos = {}

    def deepcopy(self, x, memo=None):
        if memo is None and isinstance(x, ir.Block):
            memo = self.memos.setdefault(id(x.scope), {})
        return copy.deepcopy(x, memo)

    def __getattr__(self, name):
        return getattr(copy, name)


def _inline_ir(original):
    def inline_ir(self, *args, **kwargs):
        saved = inline_closurecall.copy
        inline_closurecall.copy = SharedScopeCopy()  # the memos live for this inlining only
        try:
            return original(self, *args, **kwargs)
        finally:
            inline_closurecall.copy = saved

    inline_ir.shares_scope_copies = True
    return inline_ir


def install() -> None:
    """Wrap numba's ``InlineWorker.inline_ir`` (idempotent; nothing if numba's inliner no longer
    copies through its module's ``copy``)."""
    worker = inline_closurecall.InlineWorker
    if getattr(worker.inline_ir, "shares_scope_copies", False) or getattr(inline_closurecall, "copy", None) is not copy:
        return
    worker.inline_ir = _inline_ir(worker.inline_ir)
