"""The accuracy check: a verdict (``accurate``, ``drifted`` or ``inaccurate``) on a solution that
does not trust the scheme's own equations, measured against the exact flow (``exact/``).

- ``judgement.py``: the scales of a motion, the tests and the verdict of a trajectory in phase
  space (marches, fixed ends, every compared method), and the march's monitor of it.
- ``higher_order.py``: the same verdicts for a higher-order trajectory (positions only).
"""
