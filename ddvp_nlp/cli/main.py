"""The ``ddvp`` entry point: parse, dispatch to the command, map failures to exit codes (0
success, 1 the solve failed with partial results written, 2 bad usage with a message naming the
argument, 141 stdout closed by its reader; never a traceback)."""

from __future__ import annotations

import sys
import warnings

from ..errors import InputError
from .grids import run_compare, run_reproduce, run_scenes, run_stress, run_sweep
from .interrupts import INTERRUPTS, Stopped
from .parser import build_parser, parse_arguments
from .solve import run_periodic, run_poincare, run_solve
from .summary import format_warning

COMMANDS = {"scenes": run_scenes, "march": run_solve, "bvp": run_solve,
            "compare": run_compare, "stress": run_stress, "sweep": run_sweep,
            "reproduce": run_reproduce, "periodic": run_periodic}


COMMANDS["poincare"] = run_poincare


def _check_common(args) -> None:
    """Options several commands share, checked before anything is loaded: ``--workers`` (0 was
    silently taken as 1)."""
    from ..validation import check_integer

    if getattr(args, "workers", None) is not None:
        check_integer("--workers", args.workers)


def main(argv: list[str] | None = None) -> int:

    from ..errors import OutputError

    parser = build_parser()
    args = parse_arguments(parser, argv)
    if args.command not in COMMANDS:
        parser.error(f"unknown command {args.command!r}")
    original_format = warnings.formatwarning
    warnings.formatwarning = format_warning  # one line, no source echo
    restore = INTERRUPTS.install("raise")
    try:
        _check_common(args)
        return COMMANDS[args.command](args)
    except InputError as exc:
        print(f"ddvp {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        print(f"ddvp {args.command}: error: {exc}; the run was not saved (the folder keeps "
              "what it held before)", file=sys.stderr)
        return 1
    except Stopped as exc:
        print(f"ddvp {args.command}: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # the reader of stdout went away (`ddvp march ... | head`): the run's files are
        # written before the summary is printed; say nothing more on the closed pipe
        _silence_stdout()
        return 141  # 128 + SIGPIPE, the shell's code for a writer whose reader went away
    except KeyboardInterrupt:  # a grid keeps its rows
        print(f"ddvp {args.command}: interrupted; the rows finished so far are in the output "
              "folder (ddvp sweep, and ddvp stress --resume, go on from them)", file=sys.stderr)
        return 1
    finally:
        restore()
        warnings.formatwarning = original_format


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
