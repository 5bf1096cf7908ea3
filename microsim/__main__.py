"""``microsim`` and ``python -m microsim``: the command line's entry point (:func:`microsim.cli.main`).

Its own import is nearly free, so that Ctrl-C while the command line's modules are still
importing ends in the one line every other stop ends in, not in a traceback.
"""

import signal
import sys


def main(argv=None) -> int:
    try:
        from microsim.cli import main as command_line
    except KeyboardInterrupt:
        sys.stderr.write("microsim: error: stopped by SIGINT\n")
        sys.stderr.flush()
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.raise_signal(signal.SIGINT)
        return 128 + signal.SIGINT
    return command_line(argv)


if __name__ == "__main__":
    sys.exit(main())
