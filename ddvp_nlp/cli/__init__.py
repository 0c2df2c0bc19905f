"""The ``ddvp`` command: ``main.py`` (the entry point, the table of commands and the exit codes:
0 success, 1 the solve failed with partial results written, 2 bad usage with a message naming
the argument), ``parser.py`` (one parser per command), ``arguments.py`` (options into the
solvers' option objects, every default read from the API), one module per command
(``march_command.py``, ``bvp_command.py``, ``orbit_commands.py``, ``section_command.py``,
``study_commands.py``, ``scenes_command.py``; ``one_run.py`` what march and bvp share),
``events.py`` (``--t-eval`` and ``--event``), ``folders.py`` (default run folders),
``summary.py`` (what is printed) and ``interrupts.py`` (Ctrl-C and SIGTERM).

May import every other part of the package; nothing imports from here.
"""

from .main import main

__all__ = ["main"]
