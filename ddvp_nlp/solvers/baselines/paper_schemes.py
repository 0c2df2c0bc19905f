"""The paper's schemes as comparison methods, each run by ``march`` (``solvers/marching``).

- ``vddvp`` (rule ``vddvp``): the variable-step midpoint scheme, the energy of interval ``k``
  at the previous clock; order 2, symplectic, conserves the midpoint ``H``.
- ``lee`` (rule ``lee``): the same action with the node-time variation ``dS_D/dt_k = 0``; order
  2, symplectic, conserves energy. For autonomous ``H`` it is ``vddvp`` exactly.
- ``midpoint`` (rule ``fixed``): fixed-step implicit midpoint (the paper's DDVP with fixed
  steps); order 2, symplectic, does not conserve energy.

The knob is the first step ``tau0`` (the step ``tau`` of ``midpoint``); the march runs in
compiled chunks of the baselines' one size (``chunks.CHUNK``), so a scene compiles once. Each
also aims at a trajectory error (``run(..., target_error=E)``: the march's own choice of
``tau0`` from a pilot at the given knob value, ``marching/target.py``, with the accuracy check
on, as it must be to judge the error).
"""

from __future__ import annotations

from ..marching.initial_value import march
from ..options import DEFAULT_TOLERANCE, Compilation, StepControl
from .chunks import CHUNK
from .integrator import Integrator


def _march(rule: str):
    """``Integrator.run`` of the march with the energy ``rule``, knob ``tau0``."""
    def run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None,
            target_error=None):
        return march(
            system,
            config.q0,
            config.p0,
            (config.t0, config.t_end),
            tau0=value,
            scheme=rule,
            params=config.params,
            steps=StepControl(max_steps=max_steps, time_limit=time_limit),
            accuracy=None if target_error is None else DEFAULT_TOLERANCE,
            compilation=Compilation(compiler=compiler, cache_dir=cache_dir, chunk=CHUNK),
            target_error=target_error,
        )
    return run


def _same_as_vddvp(system) -> str | None:
    if system.time_dependent:
        return None
    return "for autonomous H its energy equation is the vddvp one (H_k = H_{k-1})"


# Where the energy rules cannot step at a given tau0 (docs/theory.md section 7).
ENERGY_RULE_LIMITATION = (
    "the energy step keeps a positive root only while the site-density weight w = f' H_zz f "
    "keeps its sign over a step; where it changes sign along the orbit (an inflection of the "
    "potential crossed at speed, a turning point; on a constrained system, where the "
    "coefficient c of theory section 12 changes sign, as on every libration of a Cartesian "
    "pendulum) a step longer than that change has no admissible root and the march stops "
    "there (no_admissible_step, or a step whose Newton does not converge); a smaller tau0, "
    "--least-squares or fixed steps pass (on a constrained system, fixed steps only)")

VDDVP = Integrator("vddvp", "the paper's variable-step midpoint scheme (energy of interval k at "
                   "the previous clock)", order=2, symplectic=True, energy_conserving=True,
                   knob="tau0", run=_march("vddvp"), aims=True, reverses_itself=True,
                   limitation=ENERGY_RULE_LIMITATION, constrained=True)
LEE = Integrator("lee", "same action, node-time variation dS_D/dt_k = 0", order=2,
                 symplectic=True, energy_conserving=True, knob="tau0", run=_march("lee"),
                 reverses_itself=True, redundant=_same_as_vddvp, aims=True,
                 limitation=ENERGY_RULE_LIMITATION, constrained=True)
MIDPOINT = Integrator("midpoint", "fixed-step implicit midpoint (the paper's DDVP with fixed "
                      "steps)", order=2, symplectic=True, energy_conserving=False, knob="tau",
                      run=_march("fixed"), aims=True, reverses_itself=True,
                      constrained=True)
