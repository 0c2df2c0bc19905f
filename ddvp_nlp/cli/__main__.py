"""``python -m ddvp_nlp.cli ...``: the ``ddvp`` command without its console script."""

import sys

from .main import main

sys.exit(main())
