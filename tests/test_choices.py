"""One list each of the names a user chooses among (microsim.core.choices), and the modules that
implement them implement exactly those."""

import typing

from microsim import config
from microsim.core import choices
from microsim.run import runner
from microsim.tracer.integrators import surface


def test_every_backend_named_is_implemented_and_no_other():
    assert tuple(surface.BACKENDS) == choices.BACKENDS
    assert typing.get_args(config.Run.model_fields["backend"].annotation) == choices.BACKEND_CHOICES


def test_every_executor_named_is_implemented_and_no_other():
    assert tuple(runner.EXECUTORS) == choices.EXECUTORS


def test_the_command_line_offers_exactly_these():
    """``--backend`` and ``--executor`` take their choices from microsim.core.choices."""
    from microsim import cli

    options = {param.name: param for param in cli.run.params}
    assert tuple(options["backend"].type.choices) == choices.BACKEND_CHOICES
    assert tuple(options["executor"].type.choices) == choices.EXECUTORS
