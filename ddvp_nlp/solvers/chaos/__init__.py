"""Chaos indicators on the march's tangent map: MEGNO, the fast Lyapunov indicator, the largest
Lyapunov exponent and the full spectrum, for the energy rules (steps fixed by the energy
equation, so the tangent vectors cannot move them), with their reference on the exact flow.
The module map is in ``docs/architecture.md``; the derivations are in the module docstrings
(``tangent.py``, ``indicators.py``, ``spectrum.py``, ``exact_indicators.py``) and the measured
validation in docs/chaos/README.md.

The contract of the chaos indicators. An implementer must keep:

1. The tangent never moves a node: the compiled step is the march's own (``FastChunk``'s step
   function, called unchanged) followed by the tangent on its root, and the nodes are those of
   ``march`` from the same start, bit for bit (tested).
2. The tangent is the derivative of the accepted step, the step length included (implicit
   differentiation of the energy equation); it is checked against finite differences of
   perturbed marches and, as ``tau0 -> 0``, against the exact flow's variational equations.
3. Every indicator is stated on the nodes with its order in the steps (``indicators.py``);
   the exact-flow reference (``exact_indicators.py``) integrates the same definitions
   continuously, with its own error control, through the one exact flow (``exact/``).
4. A failed step is a status on the result, never an exception; inputs are checked (an
   ``InputError`` naming the argument) before anything is built.
5. This package imports the core, ``marching/`` and ``exact/``, never the workbench.
"""

from .exact_indicators import exact_indicators, exact_spectrum
from .indicators import ChaosIndicators, chaos_indicators
from .spectrum import Spectrum, lyapunov_spectrum, symplectic_flag

__all__ = ["ChaosIndicators", "Spectrum", "chaos_indicators", "exact_indicators",
           "exact_spectrum", "lyapunov_spectrum", "symplectic_flag"]
