"""The ``mavins`` command line: parses options and calls in, nothing more.

One module per command (``cmd_<name>``: its options and the call into its face), the options
several commands share in :mod:`.options`. Heavy modules (numba kernels, pymavlink, rerun) are
imported only inside the subcommand that needs them, so ``mavins --help`` answers at once.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from .cmd_analyze import _add_analyze
from .cmd_demo import _add_demo
from .cmd_key import _add_key
from .cmd_nav import _add_nav
from .cmd_replay import _add_replay
from .cmd_review import _add_review
from .cmd_run import _add_run
from .cmd_sim import _add_sim
from .options import AIDING_WORDS, EXIT_USAGE, HEADING_WORDS, _Range, _show_ranges, _typed_options, _Words

__all__ = ["AIDING_WORDS", "EXIT_USAGE", "HEADING_WORDS", "_Range", "_Words", "build_parser", "main"]

COMMANDS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (
    _add_nav, _add_sim, _add_run, _add_replay, _add_demo, _add_review, _add_key, _add_analyze)


def build_parser() -> argparse.ArgumentParser:
    """The full ``mavins`` parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="mavins",
        description="MAVLink inertial navigation: strapdown INS service, offline tools and IMU simulator.",
        epilog="Run 'mavins COMMAND --help' for the options of a command.",
    )
    parser.add_argument("--version", action="version", version=f"mavins {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add in COMMANDS:
        add(sub)
    _show_ranges(parser)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mavins")
    except PackageNotFoundError:
        return "unknown"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mavins`` console script."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.typed = _typed_options(parser, argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    import signal
    import threading

    previous = None
    if args.command in OFFLINE_COMMANDS and threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _terminate)  # unwind like Ctrl-C: temporary outputs removed
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("mavins: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print("mavins: terminated", file=sys.stderr)
        return 143
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


OFFLINE_COMMANDS = ("nav", "sim", "replay", "review", "key", "analyze")


class _Terminated(BaseException):
    """SIGTERM in an offline tool: raised so that every temporary output is removed on the way out."""


def _terminate(signum: int, frame: object) -> None:
    raise _Terminated()
