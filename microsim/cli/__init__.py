"""Command line (conventions §7): ``microsim run``, ``compare``, ``fit``, ``export``, ``render`` and ``models``.

Argument parsing and printing only: a run is :func:`microsim.app.session.run`, a comparison
:func:`microsim.analysis.compare.compare`, a fit :func:`microsim.analysis.fit.fit`. The group
:data:`cli` and the entry point :func:`main`, with the one-line errors and exit statuses of
conventions §9, are :mod:`microsim.cli.entry`; each command group's module registers its
commands on :data:`cli` (:mod:`microsim.cli.run_command`, :mod:`microsim.cli.analysis`,
:mod:`microsim.cli.interop`).

The modules of the work itself (config and geometry, numba, h5py, the models) are imported by
each command as it needs them: --help, `models` and a refused argument answer without them.
"""

from microsim.cli.analysis import compare, fit, list_models
from microsim.cli.entry import EXIT_BAD_INPUT, BadInput, cli, main
from microsim.cli.interop import export, render_command
from microsim.cli.run_command import run

__all__ = ["EXIT_BAD_INPUT", "BadInput", "cli", "compare", "export", "fit", "list_models", "main", "render_command",
           "run"]
