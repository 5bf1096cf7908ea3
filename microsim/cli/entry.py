"""The command group ``microsim`` and its entry point :func:`main` (conventions §7, §9).

Bad input of any kind ends with one line on stderr naming the key or flag and what is accepted,
exit status 2 (:class:`BadInput`, or a usage error of click), no traceback, and no output file; a
run that fails ends in one line with status 1, and one stopped by SIGINT, SIGTERM or SIGHUP says
in one line how many units it kept for ``--resume`` and then dies of that signal (a shell reports
130, 143, 129; a shell loop stops on Ctrl-C as it should). A signal that was ignored when
microsim started stays ignored. Each command's module registers it on :data:`cli`; the package
imports them all.
"""

from __future__ import annotations

import signal

import click

from microsim.core.interrupts import Stopped, die_of, die_on_stop_signals, restore

#: the exit status of bad input of any kind
EXIT_BAD_INPUT = 2


class BadInput(click.ClickException):
    """Bad input: :func:`main` prints its one line and returns EXIT_BAD_INPUT."""

    exit_code = EXIT_BAD_INPUT


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="microsim")
def cli():
    """microsim: ground-truth BRDF tables from explicit random microgeometry."""


def main(argv=None) -> int:
    """Entry point of the ``microsim`` command: 0, or the exit status of its one-line error.

    A stop signal (SIGINT, SIGTERM, SIGHUP) ends the command in one line whenever it comes, and
    the process then dies of it. While a run traces and writes its tables, the session stops it
    cleanly (:class:`microsim.core.interrupts.StopOnSignals`); at any other time there is nothing to
    clean up, and the process dies at once (:func:`microsim.core.interrupts.die_on_stop_signals`).
    Where a caller of ``main`` left SIGINT to Python's KeyboardInterrupt, it is reported in the
    same line and ``main`` returns 130. The handlers are the caller's again when ``main`` returns
    or raises."""
    installed = die_on_stop_signals()
    try:
        cli.main(args=argv, prog_name="microsim", standalone_mode=False)
    except (KeyboardInterrupt, click.exceptions.Abort):
        click.echo("microsim: error: stopped by SIGINT", err=True)
        return 128 + signal.SIGINT
    except Stopped as err:
        restore(installed)
        click.echo(f"microsim: error: {err}", err=True)
        die_of(err.signum)
        return err.exit_code
    except click.ClickException as err:
        message = err.format_message().replace("\n", " ")
        click.echo(f"microsim: error: {message}", err=True)
        return EXIT_BAD_INPUT if isinstance(err, (click.UsageError, BadInput)) else err.exit_code
    finally:
        restore(installed)
    return 0
