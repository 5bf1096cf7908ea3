"""How ``compare`` and ``fit`` judge what an estimator writes: one :class:`Judge` per estimator
that has something to judge, named by the estimator's ``JUDGE`` ("module:attribute"), so that
the comparison, the fit and the CLI's flags know no estimator by name.

A judge compares on the cells (the default, no flag: :data:`microsim.analysis.compare.CELLS`) or
on something else that a flag asks for, ``--<on>`` (the points' ``--points``, the retro rings'
``--retro``). Its ``compare(table, model, order, **params)`` returns a comparison with
``as_dict`` (the JSON of docs/conventions.md §7); its ``fitted(table, first, order, n_free)``,
what a fit fits (:class:`microsim.analysis.fitted.Fitted`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable

from microsim.tracer import estimators

#: what a comparison is on without a flag
DEFAULT_ON = "cells"


@dataclass(frozen=True)
class Judge:
    """How a model is judged against one estimator's datasets (module doc)."""

    on: str  # the word of ``compare(on=...)`` and of the CLI's flag --<on> (DEFAULT_ON: no flag)
    unit: str  # what one judged value is: "cell", "point", "ring"
    dataset: str  # the dataset of all orders (its _order, _stderr datasets beside it)
    counted: str  # the JSON key of how many were judged
    keys: str  # the config that makes the datasets, for a refusal's message
    geometry: tuple  # the other datasets it reads
    help: str  # the CLI flag's help
    compare: Callable
    fitted: Callable


def judges() -> dict[str, Judge]:
    """Every registered estimator's judge, by ``on``, in the estimators' order."""
    found = {}
    for cls in estimators.classes():
        if cls.JUDGE is not None:
            module, attribute = cls.JUDGE.split(":")
            judge = getattr(importlib.import_module(module), attribute)
            found[judge.on] = judge
    return found


def flagged() -> dict[str, Judge]:
    """The judges a CLI flag asks for (every one but the cells')."""
    return {on: judge for on, judge in judges().items() if on != DEFAULT_ON}


def judge(on: str) -> Judge:
    """The judge of ``on``; ValueError (one line) naming the accepted ones."""
    found = judges()
    if on not in found:
        raise ValueError(f"on = {on!r}: accepted: {', '.join(map(repr, found))}")
    return found[on]
