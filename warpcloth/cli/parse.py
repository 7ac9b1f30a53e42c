"""The argument parser every warpcloth command line uses (``warpcloth``, ``bench/devices.py``,
``python -m warpcloth``): errors are one line, ``warpcloth: error: ...``, exit 2;
:func:`guarded` runs a command with the exit codes of every other failure; :func:`add_verbose`
the flags every subcommand takes.

Imports nothing heavy (Warp is initialised inside :func:`guarded`), so that the command line's
top level is cheap to build.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
import warnings

from warpcloth.errors import WarpclothError
from warpcloth.io.files import EXIT_IO, OutputError

#: Exit status of bad input.
EXIT_USAGE = 2
#: What every error line starts with.
ERROR_PREFIX = "warpcloth: error: "

# argparse takes "-inf", "-1e-3" or "-nan" for options (its own test accepts only "-1" and
# "-.5"), so "--dt -1e-3" said "expected one argument". Any float spelling is a value here.
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*([eE][-+]?\d+)?|\.\d+([eE][-+]?\d+)?|inf(inity)?|nan)$", re.IGNORECASE)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line, ``warpcloth: error: ...``, status 2,
    and which reads negative numbers in any float spelling (``-inf``, ``-1e-3``) as values."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def _parse_optional(self, arg_string):
        # before argparse's prefix matching, which reads "-inf" as "-i nf" (--integrator)
        if arg_string and _NEGATIVE_NUMBER.match(arg_string) and not self._has_negative_number_optionals:
            return None
        return super()._parse_optional(arg_string)

    def error(self, message):
        self.exit(EXIT_USAGE, f"{ERROR_PREFIX}{_shorten(message)}\n")


def add_verbose(p: argparse.ArgumentParser, quiet: bool = True) -> None:
    """``--verbose`` (Warp's messages) and, unless the subcommand has its own, ``--quiet``."""
    p.add_argument("--verbose", action="store_true", help="show Warp's start-up and module-load messages on stderr")
    if quiet:
        p.add_argument(
            "--quiet",
            "-q",
            action="store_true",
            help="print nothing on success (no summary, no progress); errors still print",
        )


#: A quoted value in argparse's messages longer than this is cut (a 100,000-digit number is not
#: echoed whole); in warpcloth's own messages (which quote file paths) one longer than MAX_QUOTED_ANY.
MAX_QUOTED = 60
MAX_QUOTED_ANY = 1000


def _shorten(message: str, limit: int = MAX_QUOTED) -> str:
    """``message`` with every quoted value over ``limit`` characters cut to ``limit``."""
    quoted = re.compile(rf"'([^']{{{limit}}})[^']+'")
    return quoted.sub(lambda m: f"'{m.group(1)}...' ({len(m.group(0)) - 2:,} characters)", str(message))


def print_error(message: str, stream=None) -> None:
    """Print ``warpcloth: error: message`` as one line."""
    text = _shorten(" ".join(str(message).split()), MAX_QUOTED_ANY)
    print(f"{ERROR_PREFIX}{text}", file=stream or sys.stderr)


#: Exit status after SIGTERM (128 + 15, as a shell reports a process it terminated).
EXIT_SIGTERM = 143
#: Exit status after SIGINT (Ctrl-C).
EXIT_SIGINT = 130
#: Exit status when the reader of stdout went away (128 + SIGPIPE, as a tool killed by it).
EXIT_PIPE = 141


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C: every cleanup path that runs on Ctrl-C runs on it too."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _silence_stdout() -> None:
    """After a failed write to stdout (closed pipe, full device): point fd 1 at /dev/null so
    the interpreter's final flush does not print a second error."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    except OSError:
        pass


#: NumPy's floating-point RuntimeWarnings (overflow in a cast, 0 / 0, ...), which never reach stderr.
_NUMPY_FP_WARNINGS = r".*(overflow|divide by zero|invalid value|underflow) encountered"


class _ClosedStdout:
    """``sys.stdout`` of a process started with fd 1 closed: a write is an :class:`OutputError`
    (one line, exit 74), not a silent loss or a traceback."""

    def write(self, text: str) -> int:
        if not text:
            return 0
        err = OutputError("cannot write to stdout: it is closed")
        err.stdout = True
        raise err

    def flush(self) -> None:
        pass

    def fileno(self) -> int:
        raise OSError(9, "stdout is closed")

    def isatty(self) -> bool:
        return False


def guarded(args, body, interrupted_hint: str = "") -> int:
    """Run ``body()`` as a command: one-line errors (status 2 for bad input, 74 for an output
    that could not be written), a quiet exit when stdout's reader went away (141), and SIGTERM
    handled like Ctrl-C (143 and 130; temporary files are removed on the way out)."""
    from warpcloth.sim.device import init_warp  # noqa: PLC0415  (Warp starts when a command runs, not for --version or --help)

    init_warp(getattr(args, "verbose", False))
    if sys.stdout is None:  # started with stdout closed (`warpcloth list >&-`): writing to it is an error
        sys.stdout = _ClosedStdout()
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        try:
            with (
                warnings.catch_warnings()
            ):  # NumPy's floating-point warnings (inf and nan are checked where they matter)
                warnings.filterwarnings("ignore", message=_NUMPY_FP_WARNINGS, category=RuntimeWarning)
                code = body()
            try:
                sys.stdout.flush()
            except BrokenPipeError:
                raise
            except OSError as exc:  # e.g. `warpcloth run sheet --json > /dev/full`
                err = OutputError(f"cannot write to stdout: {exc.strerror or exc}")
                err.stdout = True
                raise err from None
            return code
        except OutputError as exc:
            if getattr(exc, "stdout", False):
                _silence_stdout()
            print_error(exc)
            return EXIT_IO
        except WarpclothError as exc:
            print_error(exc)
            return EXIT_USAGE
        except BrokenPipeError:
            _silence_stdout()
            return EXIT_PIPE
        except OSError as exc:
            # An I/O error no writer turned into a message: still one line. Every file writer
            # of warpcloth reports its own path, so one without a file name is stdout (print).
            where = exc.filename or "stdout"
            if exc.filename is None:
                _silence_stdout()
            print_error(f"cannot write to {where}: {exc.strerror or exc}")
            return EXIT_IO
        except KeyboardInterrupt as exc:
            what = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted"
            print(f"warpcloth: {what}{interrupted_hint}", file=sys.stderr)
            return EXIT_SIGTERM if isinstance(exc, Terminated) else EXIT_SIGINT
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


__all__ = [
    "ERROR_PREFIX",
    "EXIT_IO",
    "EXIT_PIPE",
    "EXIT_SIGINT",
    "EXIT_SIGTERM",
    "EXIT_USAGE",
    "Parser",
    "Terminated",
    "add_verbose",
    "guarded",
    "print_error",
]
