"""Kernels chosen by the type of a record: how the walk calls "the method" of a plugin it does not know.

A :class:`Generic` is a numba function whose implementation is chosen, when a kernel is
compiled, by the class of its first argument (a ``NamedTuple`` record: an estimator's tally).
Each plugin registers its own implementation for its record class, in its own module; the caller
names the generic function only (:mod:`microsim.tracer.estimators.hooks`): pbrt-v4's
``TaggedPointer::Dispatch``, resolved at compile time, and the kernels stay cacheable. An
implementation is compiled as a function of its own and called (LLVM may inline it), not inlined
by numba: numba 0.68's ``overload(inline="always")`` lost a kernel's writes to a path's weight
(an inlined overload followed by an inlined njit function with an early return that wrote the
same array read back the old value; tests/test_dispatch.py). A call costs little where it is
rare (an exit, once per path); the walk's own steps, once per segment, are inlined
(:mod:`microsim.tracer.integrators.walk`).
"""

from __future__ import annotations

import functools
import inspect

from numba.extending import overload

from microsim.tracer.jit import kernel_cache

#: how implementations compile: as the tracer's kernels (no reference counting, numpy's errors)
JIT_OPTIONS = {"error_model": "numpy", "_nrt": False}


class Generic:
    """The generic function of ``stub`` (a Python function whose signature every implementation
    shares); ``default``: the implementation for a record class that registered none (None: such
    a call does not compile)."""

    def __init__(self, stub, default=None):
        self.name, self.implementations, self.default = stub.__name__, {}, default
        self.in_microsim = kernel_cache.is_source(inspect.getfile(stub))

        @functools.wraps(stub)
        def select(*args):
            implementation = self.implementations.get(getattr(args[0], "instance_class", None), self.default)
            return None if implementation is None else getattr(implementation, "py_func", implementation)

        overload(stub, jit_options=JIT_OPTIONS)(select)

    def register(self, record_class):
        """Decorator: the implementation for records of ``record_class``, a Python function in
        numba's subset (numba compiles it for each call's types, with JIT_OPTIONS)."""
        def add(implementation):
            self.implementations[record_class] = implementation
            if self.in_microsim:  # a hook of microsim's kernels: an edit of its file recompiles them
                kernel_cache.add_plugin_source(inspect.getfile(getattr(implementation, "py_func", implementation)))
            return implementation
        return add


def over_each(stub, one, parallel: int = 1) -> None:
    """Make numba compile ``stub(records, ...)`` (a Python function's signature) as ``one(record,
    ...)`` for every record of the tuple ``records`` in turn (``one``: a generic function's stub),
    unrolled when the kernel compiles; with ``parallel`` = 2, the second argument is a tuple as
    long, whose item goes with its record: ``one(records[k], setups[k], ...)``."""
    names = list(inspect.signature(stub).parameters)
    tuples, rest = names[:parallel], ", ".join(names[parallel:])
    arguments = ", ".join(names)
    firsts, tails = ", ".join(f"{t}[0]" for t in tuples), ", ".join(f"{t}[1:]" for t in tuples)
    namespace = {"one": one, "every": stub}
    exec(f"def nothing({arguments}):\n    return None\n"
         f"def each({arguments}):\n    one({firsts}, {rest})\n    every({tails}, {rest})\n", namespace)

    @functools.wraps(stub)
    def select(*args):
        return namespace["nothing"] if len(args[0]) == 0 else namespace["each"]

    overload(stub, jit_options=JIT_OPTIONS)(select)
