"""What several commands take alike: a model by name and its ``--param`` values, a table, and an
output path checked before the work; each refusal a :class:`~microsim.cli.entry.BadInput` of one line."""

from __future__ import annotations

import contextlib
from pathlib import Path

import click

from microsim.cli.entry import BadInput
from microsim.core import files

MODEL_HELP = ("analytic model: a name `microsim models` lists, or your own as module:Name or path.py:Name (a "
              "BRDFModel subclass, or a function f(wi, wo, **params) in 1/sr)")


def model_class(text: str):
    """The model class ``--model`` names (a registered model, module:Name or path.py:Name), or
    BadInput in one line."""
    from microsim.models import user_models

    try:
        return user_models.load(text)
    except ValueError as err:  # an unknown name, or a user model that does not load
        message = str(err)
        raise BadInput(f"--model: {message}" if message.startswith("unknown model") else f"--model {text}: {message}") \
            from None


@contextlib.contextmanager
def user_model_errors(text: str):
    """A user's model (``--model`` module:Name or path.py:Name) that raises while it is
    evaluated ends in one line naming it, as a bad input; the registered models' errors are
    microsim's own and keep their traceback."""
    if ":" not in text:
        yield
        return
    try:
        yield
    except click.ClickException:
        raise
    except Exception as err:  # noqa: BLE001 - the user's code
        raise BadInput(f"--model {text}: evaluating it raised {type(err).__name__}: {' '.join(str(err).split())}") \
            from None


def model_parameters(params) -> dict:
    """--param KEY=VALUE items as a dictionary (values as text; the model checks them)."""
    values = {}
    for item in params:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise BadInput(f"--param {item!r}: expected KEY=VALUE")
        values[key.strip()] = value.strip()
    return values


def check_output(out: Path, force: bool, inputs: dict) -> None:
    """BadInput, before the work, unless ``out`` can be written (:func:`microsim.core.files.refusal`):
    never over one of ``inputs``, with --force or not."""
    if why := files.refusal(out, force=force, inputs=inputs):
        raise BadInput(why)


def load_table(table_path):
    """The table at ``table_path``, or BadInput in one line."""
    from microsim import tables

    try:
        return tables.load(table_path)
    except FileNotFoundError:
        raise BadInput(f"TABLE.h5: {table_path} not found") from None
    except tables.TableError as err:
        raise BadInput(f"TABLE.h5: {table_path}: {err}") from None
    except OSError as err:
        raise BadInput(f"TABLE.h5: {table_path} is not a microsim table ({err})") from None
