"""The ``varflow`` command line.

Commands, each with its synopsis in the notes of its module (and ``varflow
COMMAND --help``): ``flow``, ``show``, ``eval``, ``demo`` and ``methods``
(:mod:`~varflow.cli.flow`); ``track`` (:mod:`~varflow.cli.track`); ``interpolate`` and
``retime`` (:mod:`~varflow.cli.interpolate`); ``denoise`` (:mod:`~varflow.cli.denoise`);
``restore`` (:mod:`~varflow.cli.restore`);
``bench middlebury | middlebury-multiframe | trajectories | twoframe |
sintel-trajectories`` (:mod:`~varflow.cli.bench`); ``video`` (:mod:`~varflow.cli.video`);
``batch flow | track | retime | denoise`` (:mod:`~varflow.cli.batch`); ``report``
(:mod:`~varflow.cli.report`).

Method parameters become flags automatically: every field of the parameter
dataclass of every registered method is offered as ``--field-name`` (booleans as
``--name/--no-name``); only the flags given on the command line are passed on.
``--help`` states each flag's default per method (only the chosen method's when
``--method NAME`` comes before ``--help``).

Every error ends the program with one line ``varflow: error: ...`` on stderr and
exit status 2 (130 on Ctrl-C).  Results go to stdout; ``-v`` turns on the library's
INFO logging on stderr.  Files are written atomically.

Layout: :mod:`varflow.cli._common` holds what the commands share (parser, parameter
flags, progress bar, output checks, one-line errors); every command group has its
module with an ``add_parser(sub, common, argv)`` that registers its sub-commands
(``sub``: the sub-parsers action of ``varflow``; ``common``: the parent parser of the
options every command has, ``-v``; ``argv``: the command line, so that ``--help``
can show the defaults of the ``--method``/``--methods`` it names), called by
:func:`build_parser` in the order of ``varflow --help``:
:mod:`~varflow.cli.flow` (flow, show, eval, demo, methods), :mod:`~varflow.cli.track`,
:mod:`~varflow.cli.interpolate` (interpolate, retime), :mod:`~varflow.cli.denoise`,
:mod:`~varflow.cli.restore`, :mod:`~varflow.cli.bench`, :mod:`~varflow.cli.video`,
:mod:`~varflow.cli.batch` and
:mod:`~varflow.cli.report`.  A new command (e.g. ``interpolate``, ``retime``) gets a
module of its own, added to :func:`build_parser`.  The library never imports
this package.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Callable, Sequence

from .._version import __version__
from ._common import (
    PROG,
    _fail,
    _one_line,
    _Parser,
    _reset_claims,
    flag_names,
    parameter_table,
)
from .flow import DEMO_MAGNITUDE, DEMO_SEED, DEMO_SHAPE

__all__ = ["build_parser", "main", "parameter_table"]
__all__ += ["DEMO_MAGNITUDE", "DEMO_SEED", "DEMO_SHAPE"]

log = logging.getLogger("varflow.cli")

def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser (parameter flags generated from the registry).

    Parameters
    ----------
    argv : sequence of str, optional
        The command line about to be parsed: a ``--method NAME`` in it makes
        ``--help`` show that method's defaults (every method's otherwise).

    Returns
    -------
    ArgumentParser
    """
    common = _Parser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                        help="log to stderr: -v INFO, -vv DEBUG")

    parser = _Parser(
        prog=PROG,
        description="Classical variational optical flow (TV-L1 and friends).",
        epilog="Run 'varflow demo' for a first look; 'varflow COMMAND --help' for details.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log to stderr: -v INFO, -vv DEBUG")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                parser_class=_Parser)
    from . import batch, bench, denoise, flow, interpolate, report, restore, track, video

    for module in (flow, track, interpolate, denoise, restore, bench, video, batch, report):
        module.add_parser(sub, common, argv)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; ``sys.argv[1:]`` by default.

    Returns
    -------
    int
        0 on success, 2 on any error (one line on stderr), 130 on Ctrl-C, 141 when
        stdout is a closed pipe.
    """
    handler: logging.Handler | None = None
    pkg_log = logging.getLogger("varflow")
    old_level = pkg_log.level
    _reset_claims()
    args: argparse.Namespace | None = None
    try:
        try:
            argv = list(sys.argv[1:] if argv is None else argv)
            args = build_parser(argv).parse_args(argv)
        except SystemExit as exc:  # --help, --version
            return int(exc.code or 0) if not isinstance(exc.code, str) else _fail(exc.code)
        if getattr(args, "verbose", 0):
            handler = logging.StreamHandler(sys.stderr)
            handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
            pkg_log.addHandler(handler)
            pkg_log.setLevel(logging.INFO if args.verbose == 1 else logging.DEBUG)
        func: Callable[[argparse.Namespace], int] = args.func
        return func(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `varflow methods | head -1`: stop quietly
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes
        except (OSError, ValueError):
            pass
        return 141
    except Exception as exc:  # noqa: BLE001 - the CLI turns every error into one line
        if handler is not None:
            log.info("details", exc_info=exc)
        return _fail(flag_names(_one_line(exc), args))
    finally:
        if handler is not None:
            pkg_log.removeHandler(handler)
            pkg_log.setLevel(old_level)
