"""The ``ddvp`` command, one module per concern: ``parser.py`` (the command line), ``solve.py``
(march, bvp, periodic, poincare), ``grids.py`` (compare, stress, sweep, reproduce, scenes),
``summary.py`` (what is printed), ``interrupts.py`` (Ctrl-C and SIGTERM), ``main.py`` (the entry
point and its exit codes: 0 success, 1 the solve failed with partial results written, 2 bad
usage with a message naming the argument).

May import every other part of the package; nothing imports from here.
"""

from .main import main

__all__ = ["main"]
