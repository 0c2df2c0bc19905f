"""The ``ddvp`` entry point: parse, check every numeric option, dispatch to the command, map
failures to exit codes, never a traceback:

- 0: success;
- 1: the solve failed, was interrupted (Ctrl-C, SIGTERM), or its output could not be written
  (a full disk, a read-only or busy folder, a name too long): the message says what the
  output folder holds;
- 2: bad usage or bad input (an option, a scene file, a grid file, a guess), with a message
  naming it;
- 141: stdout was closed by its reader.

Run as a command (``main()``), it works in a child process that its parent watches
(``cli/supervisor.py``): whatever it runs cannot keep it from ending or make it end lying.
"""

from __future__ import annotations

import os
import sys
import warnings
from importlib import import_module

from ..errors import InputError, OutputError
from .arguments import check_options, on_cluster
from .interrupts import INTERRUPTS, Stopped
from .parser import build_parser, command_in, parse_arguments
from .request import Request
from .summary import format_warning

# Each command: the module of this package that runs it and its function, imported when the
# command runs (`ddvp march` loads nothing of the studies, `ddvp scenes` nothing of a solver).
COMMANDS = {"scenes": "scenes_command:run_scenes", "march": "march_command:run_march_command",
            "bvp": "bvp_command:run_bvp", "compare": "study_commands:run_compare",
            "stress": "study_commands:run_stress", "sweep": "study_commands:run_sweep",
            "reproduce": "study_commands:run_reproduce",
            "periodic": "orbit_commands:run_periodic",
            "poincare": "section_command:run_poincare", "chaos": "chaos_command:run_chaos"}


def command(name: str):
    """The function that runs command ``name``."""
    module, function = COMMANDS[name].split(":")
    return getattr(import_module(f"{__package__}.{module}"), function)
# Set to 1 to see the traceback of whatever ended a command, besides its one line.
TRACEBACK_VARIABLE = "DDVP_TRACEBACK"


def main(argv: list[str] | None = None) -> int:
    """The ``ddvp`` command on ``argv`` (default: the command line, run in a supervised child
    process, ``cli/supervisor.py``); its exit code."""
    if argv is None:
        from . import supervisor

        _stdout_usable()  # before the supervisor flushes them (``ddvp scenes >&-``)
        if supervisor.available():
            return supervisor.supervise(lambda: main(sys.argv[1:]))
    original_format = warnings.formatwarning
    restore = lambda: None  # noqa: E731 - until the handlers are in place
    try:
        restore = INTERRUPTS.install()
        _stdout_usable()
        words = sys.argv[1:] if argv is None else list(argv)
        parser = build_parser(command_in(words))
        args = parse_arguments(parser, words)
        if args.command not in COMMANDS:
            parser.error(f"unknown command {args.command!r}")
        request = Request.read(args, parser.commands[args.command])  # once; never assigned to
        warnings.formatwarning = format_warning  # one line, no source echo
    except SystemExit:  # argparse's own end (--help, --version, a usage error), as it is
        restore()
        raise
    except BaseException as exc:  # noqa: B036 - a signal while starting
        INTERRUPTS.end()
        try:
            return _failure("ddvp", exc)
        finally:
            INTERRUPTS.restore()
    try:
        return _run(request)
    finally:
        restore()
        warnings.formatwarning = original_format


def _run(request: Request) -> int:
    label = f"ddvp {request.command}"
    try:
        check_options(request)
        with on_cluster(request) as request:
            code = command(request.command)(request)
        sys.stdout.flush()  # a full disk behind stdout fails here, not at the exit
        if INTERRUPTS.requested and code == 0:
            # a signal that surfaced inside CasADi as a task's error: the study went on and
            # wrote its files, but the user asked it to stop, and a run may have been cut
            _say(f"{label}: interrupted ({INTERRUPTS.name or 'SIGINT'}) while running; the "
                 "files above were written whole, but the run the signal reached may show it "
                 "as its own failure (a Newton or step failure in its row)")
            return 1
        return code
    except BaseException as exc:  # noqa: B036 - every way out gets an exit code and a line
        INTERRUPTS.end()
        return _failure(label, exc)


def _failure(command: str, exc: BaseException) -> int:
    """The exit code and message of a command that raised ``exc``."""
    if os.environ.get(TRACEBACK_VARIABLE) == "1":  # where it came from, for a defect report
        import traceback

        traceback.print_exception(exc)
    if isinstance(exc, BrokenPipeError) or (isinstance(exc, OSError) and exc.errno == 32):
        # the reader of stdout went away (`ddvp march ... | head`): the run's files are
        # written before the summary is printed; say nothing more on the closed pipe
        _silence_stdout()
        return 141  # 128 + SIGPIPE, the shell's code for a writer whose reader went away
    if isinstance(exc, InputError) and not INTERRUPTS.requested:
        _say(f"{command}: error: {exc}")
        return 2
    if isinstance(exc, OutputError):
        _say(f"{command}: error: {exc}")
        return 1
    if isinstance(exc, Stopped):
        _say(f"{command}: {exc}")
        return 1
    if isinstance(exc, KeyboardInterrupt):
        # a command that kept something says so itself (Stopped); this one wrote nothing new
        _say(f"{command}: interrupted ({INTERRUPTS.name or 'SIGINT'}) before anything was "
             "written; the output folder keeps what it held before")
        return 1
    if INTERRUPTS.requested:  # an interrupt that surfaced as another error (inside CasADi)
        # CasADi's wrapper turns a signal inside a call into its own error (NotImplementedError
        # "Wrong number or type of arguments for function 'Function_call'"): its words are not
        # the user's news, which is the interrupt (the error's type stays, for a defect report)
        _say(f"{command}: interrupted ({INTERRUPTS.name or 'SIGINT'}) inside a compiled call "
             f"(which ended with {type(exc).__name__}); every file written before it is whole")
        return 1
    if isinstance(exc, SystemExit):
        return exc.code if isinstance(exc.code, int) else 1
    if isinstance(exc, MemoryError):
        _say(f"{command}: error: out of memory ({exc or 'no detail'}); nothing new was "
             "written")
        return 1
    if isinstance(exc, OSError):  # writing stdout or stderr: a full disk, a closed file
        _silence_stdout()
        _say(f"{command}: error: cannot write the output: {exc.strerror or exc}")
        return 1
    if isinstance(exc, RecursionError):
        _say(f"{command}: error: input nested too deeply to read ({exc})")
        return 2
    _say(f"{command}: internal error: {type(exc).__name__}: {exc} (a defect of ddvp; "
         f"{TRACEBACK_VARIABLE}=1 shows where)")
    return 1


def _say(text: str) -> None:
    try:
        print(text, file=sys.stderr, flush=True)
    except (OSError, ValueError, AttributeError):  # stderr closed too: the code says it
        pass


def _stdout_usable() -> None:
    """A command started with stdout closed (``ddvp scenes >&-``) prints into /dev/null
    instead of failing on its first line."""
    if sys.stdout is None or _closed(sys.stdout):
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - for the process's lifetime
        except OSError:
            pass
    if sys.stderr is None or _closed(sys.stderr):
        try:
            sys.stderr = open(os.devnull, "w")  # noqa: SIM115
        except OSError:
            pass


def _closed(stream) -> bool:
    """Whether ``stream`` is a file whose descriptor is closed (a stream without one, such as
    a test's capture, is usable)."""
    import io

    try:
        descriptor = stream.fileno()
    except (io.UnsupportedOperation, AttributeError):
        return False
    except (OSError, ValueError):
        return True
    try:
        os.fstat(descriptor)
        return False
    except OSError:
        return True


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
