"""The integrators the comparison runs: the paper's own schemes and what users would pick
instead, each with its traits, in one registry (`INTEGRATORS`).

The contract of a compared method. An implementer adding one must:

1. Declare one `Integrator` constant beside the
   implementation: name, one-line description, ``order``, ``symplectic``,
   ``energy_conserving``, the ``knob`` a user turns for accuracy (``"tau0"``, ``"tau"`` or
   ``"rtol"``), ``applies(system)`` (``None`` or why the method does not apply, checked before
   any build) and ``redundant(system)`` (``None`` or why it repeats another method there).
2. Give it ``run(system, config, value, *, compiler, cache_dir, max_steps, time_limit=None) ->
   Solution``: ``config`` is read by attribute only (``q0``, ``p0``, ``t0``, ``t_end``,
   ``params``), ``value`` is the knob's value.
3. March through the one step loop (``solvers/driver.py``, a stepper keeping its numbered
   rules): the nodes in order, each accepted by the method's own test, a failure as a status
   with the accepted nodes kept, never an exception; the run ends at the first node at or past
   ``t_end``.
4. Compile like the march: the step map generated as C where a compiler is given
   (``chunks.load``), CasADi's virtual machine otherwise, the same numbers either way.
5. Write no equation here: step maps and residuals come from ``discrete/``; the nodes'
   own residual is recomputed by ``studies/methods.own_residuals``.
6. Add the constant to `INTEGRATORS` below (the command line's ``--scheme``, ``ddvp
   compare``, ``stress`` and ``sweep`` read the registry; ``studies/methods.py`` adds the
   sweeps' default knob values).

This package imports only the core (``driver``, ``compiler``, ``options``) and ``marching/`` (the
paper's schemes are marches).

Modules: ``integrator.py`` (the traits), ``chunks.py`` (what every compiled baseline shares),
``paper_schemes.py`` (vddvp, lee, midpoint: the march), ``fixed_step.py`` (Stormer-Verlet,
leapfrog, RK4, AVF on uniform steps; ``avf_stepper.py`` the AVF step), ``verlet_adaptive.py``
(reversible adaptive Stormer-Verlet), ``lee_left_stepper.py`` (T.D. Lee's left-point scheme),
``rattle.py`` (RATTLE and SHAKE, constrained systems only), ``dop853.py`` (scipy's DOP853,
the method users would pick instead; the studies' reference is the exact flow of
``solvers/exact/``).
"""

from . import dop853, fixed_step, paper_schemes, rattle, verlet_adaptive
from . import lee_left_stepper as lee_left
from .integrator import Integrator

INTEGRATORS: tuple[Integrator, ...] = (
    paper_schemes.VDDVP,
    paper_schemes.LEE,
    paper_schemes.MIDPOINT,
    fixed_step.STORMER_VERLET,
    fixed_step.LEAPFROG,
    verlet_adaptive.VERLET_ADAPTIVE,
    fixed_step.AVF,
    fixed_step.RK4,
    dop853.DOP853,
    lee_left.LEE_LEFT,
    rattle.RATTLE,
    rattle.SHAKE,
)

__all__ = ["INTEGRATORS", "Integrator"]
