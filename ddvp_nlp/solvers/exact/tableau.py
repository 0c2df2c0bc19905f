"""DOP853's coefficients (Dormand and Prince; Hairer, Norsett and Wanner, *Solving Ordinary
Differential Equations I*, section II.10), read from the file scipy ships, loaded on its own:
importing it through ``scipy.integrate`` would load scipy.integrate's solvers with scipy.sparse
and scipy.linalg behind them (113 modules, which a march does not otherwise load)."""

from __future__ import annotations

import importlib.util
import sys
from functools import lru_cache
from pathlib import Path
from types import SimpleNamespace

import numpy as np


def _module():
    name = "ddvp_nlp_dop853_coefficients"
    if name not in sys.modules:
        spec = importlib.util.find_spec("scipy")
        path = Path(spec.origin).parent / "integrate" / "_ivp" / "dop853_coefficients.py"
        module = importlib.util.module_from_spec(
            importlib.util.spec_from_file_location(name, path))
        module.__spec__.loader.exec_module(module)
        sys.modules[name] = module
    return sys.modules[name]


@lru_cache(maxsize=1)
def dop853() -> SimpleNamespace:
    """The tableau as plain float arrays:

    - ``A`` (12, 12), ``B`` (12,), ``C`` (12,): the order-8 formula (stages 0..11);
    - ``E5``, ``E3`` (13,): the embedded error estimators (stage 12 is ``f`` at the new point);
    - ``A_EXTRA`` (3, 16), ``C_EXTRA`` (3,): the three extra stages 13..15 of the continuous
      extension; ``D`` (4, 16): its coefficients (the dense output is of order 7).
    """
    m = _module()
    s = m.N_STAGES
    return SimpleNamespace(
        stages=s, A=np.array(m.A[:s, :s], float), B=np.array(m.B, float),
        C=np.array(m.C[:s], float), E5=np.array(m.E5, float), E3=np.array(m.E3, float),
        A_EXTRA=np.array(m.A[s + 1:], float), C_EXTRA=np.array(m.C[s + 1:], float),
        D=np.array(m.D, float), extended=m.N_STAGES_EXTENDED, power=m.INTERPOLATOR_POWER)
