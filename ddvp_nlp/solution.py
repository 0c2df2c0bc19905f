"""The result of every solve: nodes, status, the verdict of the accuracy check and the solver's
counts."""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InputError


class Status(enum.Enum):
    """How a solve ended. Every value but ``SUCCESS`` and ``EVENT`` is a failure; its text says
    what happened in words a person can act on (the message of the result adds step, time and
    state)."""

    SUCCESS = "solved: the solver's result passed every check"
    EVENT = "a terminal event occurred"
    NO_ADMISSIBLE_STEP = "the step equations have no root with tau > 0 near the previous step"
    NEWTON_FAILED = "Newton's method did not converge on the step equations"
    NON_FINITE = "a step produced a non-finite value"
    RESIDUAL_TOO_LARGE = "a step's own unscaled residual is above the tolerance"
    STEP_BELOW_MIN = "the step length fell below tau_min"
    STEP_ABOVE_MAX = "the step length rose above tau_max"
    STEP_RATIO = "the step length changed by more than max_step_ratio in one step"
    MAX_STEPS = "max_steps was reached before t_end"
    TIME_LIMIT = "the time limit was reached"
    ENERGY_GUARD = "H left the band energy_guard allows around its initial value"
    INACCURATE = ("an accuracy estimate passed its tolerance: the steps satisfy the scheme's "
                  "equations but do not follow the motion")
    DRIFTED = ("the trajectory error passed its tolerance (every step follows the flow and the "
               "energy is right: the phase drifted), and an accurate trajectory was required")
    INTERRUPTED = "interrupted by the user"
    SOLVER_FAILED = "the NLP solver did not converge"
    NOT_VERIFIED = "the solver's point does not satisfy the equations to the tolerance"

    @property
    def code(self) -> str:
        return self.name.lower()


def bound_reached(steps: int, max_steps: int, started: float, time_limit: float | None):
    """``(status, detail)`` if a run has used its steps or its seconds (``started`` from
    ``time.perf_counter()``), else ``None``."""
    import time

    if steps >= max_steps:
        return Status.MAX_STEPS, f"max_steps = {max_steps}"
    if time_limit is not None and time.perf_counter() - started > time_limit:
        return Status.TIME_LIMIT, f"time_limit = {time_limit:g} s"
    return None


@dataclass(frozen=True)
class Failure:
    """The first failed test of a verdict: the ``test`` (``"local error"``, ``"nodal energy
    drift"``, ...), the step and the time it starts from, the measured ``value`` against its
    ``limit`` (relative to the motion's scales), and ``detail``, the reason in words where a
    figure does not say it (no continuous solution near, an orbit that does not close)."""

    step: int | None
    t: float | None
    test: str
    value: float | None
    limit: float | None
    detail: str | None = None

    def as_dict(self) -> dict:
        """The failure as ``meta.json`` writes it (``detail`` only where there is one)."""
        found = {"step": self.step, "t": self.t, "test": self.test, "value": self.value,
                 "limit": self.limit}
        return found if self.detail is None else {**found, "detail": self.detail}


VERDICTS = ("accurate", "drifted", "inaccurate")


@dataclass(frozen=True)
class Verdict:
    """The verdict of the accuracy check on a trajectory (``solvers/accuracy/judgement.py``),
    set once per solve (``Solution.verdict``). Every figure is relative to the motion's scales.

    Attributes:
        name: ``"accurate"``, ``"drifted"`` or ``"inaccurate"``.
        first_failure: the first failed test (`Failure`), ``None`` unless ``inaccurate``.
        t_drift, drift_step: the time and node from which the trajectory error passes
            ``global_tol`` (or the reference was lost), else ``None``.
        error_max, error_max_t: the largest trajectory error measured (up to
            ``reference_until``) and its time: for a ``drifted`` run against a reference flow,
            the error at ``t_drift`` (the scan stops there), not the run's largest.
        estimate: what the trajectory error was measured against, in words.
        reference_until: the last time the error was measured to.
        reference_error: the reference's own largest claimed error.
        reference_lost: where the reference's own error passed its share, else ``None``.
        scale: ``S_i`` per component of ``z = (q, p)`` (of ``q`` for a higher-order run).
        energy_scale: ``E_s``.
        local_error_max: the largest local error, relative to ``S``.
        level, level_reference, level_error: the energy level the first step set, ``H`` of
            the exact motion at its clock, their difference relative to ``E_s``.
        level_round_off: the round-off floor of ``level_error`` (``2 eps max |H| / E_s``): a
            large constant in ``H`` puts the level test's resolution there, not at 0.
        energy_drift: the largest nodal ``|H - H_0| / E_s`` (autonomous ``H``).
        steps: the steps judged.
        rtol, atol, energy_tol, global_tol, require_accurate: the `Tolerance` it was judged by.
        streamed: judged a window at a time (a thinned march).
        partial: the solve failed (``Solution.status`` says how: a failed step,
            ``max_steps``, an interrupt, a grid that did not converge); ``name`` is the verdict
            on the nodes it kept (a march's accepted steps), not on the solve asked for.
    """

    name: str
    first_failure: Failure | None
    t_drift: float | None
    drift_step: int | None
    error_max: float
    error_max_t: float | None
    estimate: str
    reference_until: float | None
    reference_error: float | None
    reference_lost: float | None
    scale: tuple | None
    energy_scale: float | None
    local_error_max: float
    level: float | None
    level_reference: float | None
    level_error: float | None
    energy_drift: float | None
    steps: int
    rtol: float
    atol: float | None
    energy_tol: float
    global_tol: float
    require_accurate: bool
    streamed: bool = False
    level_round_off: float | None = None
    partial: bool = False

    def __post_init__(self):
        if self.name not in VERDICTS:
            raise ValueError(f"a verdict is one of {', '.join(VERDICTS)}, got {self.name!r}")

    @classmethod
    def of(cls, report: dict) -> Verdict:
        """The verdict of a check's report (the keys of `as_dict`; an unknown key is an
        error, so a figure cannot be dropped on the way)."""
        found = dict(report)
        failure = found.pop("first_failure")
        scale = found.pop("scale")
        return cls(name=found.pop("verdict"),
                   first_failure=None if failure is None else Failure(**failure),
                   scale=None if scale is None else tuple(scale), **found)

    @property
    def accurate(self) -> bool:
        return self.name == "accurate"

    @property
    def drifted(self) -> bool:
        return self.name == "drifted"

    @property
    def inaccurate(self) -> bool:
        return self.name == "inaccurate"

    def as_dict(self) -> dict:
        """The verdict as ``meta.json`` writes it (key ``accuracy``): ``verdict``, then the
        fields in order (``streamed`` only for a streamed check, ``partial`` only for a solve
        that did not reach its end)."""
        found = {"verdict": self.name,
                 "first_failure": None if self.first_failure is None else
                 self.first_failure.as_dict()}
        for name in _REPORTED:
            found[name] = getattr(self, name)
        if self.scale is not None:
            found["scale"] = list(self.scale)
        if self.streamed:
            found["streamed"] = True
        if self.partial:
            found["partial"] = True
        return found

    def time_reversed(self) -> Verdict:
        """The verdict of a march run backwards in time (``t -> -t``), read in the original
        time."""
        def flip(x):
            return -x if isinstance(x, (int, float)) and not isinstance(x, bool) else x
        failure = self.first_failure
        if failure is not None:
            failure = replace(failure, t=flip(failure.t))
        return replace(self, t_drift=flip(self.t_drift), error_max_t=flip(self.error_max_t),
                       reference_until=flip(self.reference_until), first_failure=failure)


_REPORTED = tuple(f for f in Verdict.__dataclass_fields__
                  if f not in ("name", "first_failure", "streamed", "partial"))


@dataclass(frozen=True)
class OrbitRecord:
    """What a periodic solve found (``Solution.orbit``; ``solvers/periodic/orbit.py``).

    Attributes:
        period: ``T = t_N - t_0``.
        energy: the prescribed energy ``E``.
        section: the section's label (``"q1=0"``, ...).
        unfolding: the unfolding parameter ``lambda`` of ``H``.
        integral_unfoldings: the unfolding parameter ``mu`` of each first integral.
        residual_limit: the limit the unscaled residuals were verified against: one number
            for every kind, or by kind (the keys of ``residuals``; each the limit of the row
            of that kind furthest over or nearest it, in that row's units).
        winding: the turns ``w`` of each coordinate (``q_N = q_0 + 2 pi w``; zero off an
            angle).
        residuals: the largest unscaled residual of each kind (``canonical``, ``energy``,
            ``prescribed_energy``, ``closure``, ``section``).
        tau_min, tau_max: the shortest and longest step.
    """

    period: float
    energy: float
    section: str
    unfolding: float
    integral_unfoldings: tuple
    residual_limit: float | dict
    winding: tuple
    residuals: dict
    tau_min: float
    tau_max: float


@dataclass
class MarchRecord:
    """What a march found besides its nodes (``Solution.march``; ``solvers/marching``), filled
    in as the run goes; `as_stats` gives it under the keys ``meta.json`` has always used.

    Attributes:
        theta: the parameter values the march used.
        solvability_warning: where the energy step's solvability weight changed sign (the
            node, time and weights), else ``None``.
        least_squares: the steps replaced by the least-squares step, one record each.
        kept: a thinned march's record of what it kept (``keep_every``, ``keep``, the nodes
            marched, the largest residuals over every step), else ``None``.
        carried: what a continued march needs besides the last nodes (`MarchState`).
        checkpoints, checkpoints_landed_s: the checkpoints written and when each landed
            (seconds), where the run saved any.
        target_error: the choice of ``tau0`` for a target error and its cost (the runs
            tried), where one was asked for.
        backward: the march ran backwards in time (``t_end < t_0``).
        start_velocity: a march started from ``v0``: ``{"v0": [...], "tau0": ...}`` (its
            derivatives are in ``v0``, ``marching/velocity_start.py``), else ``None``.
    """

    theta: list
    solvability_warning: dict | None = None
    least_squares: list = field(default_factory=list)
    kept: dict | None = None
    carried: dict | None = None
    checkpoints: int | None = None
    checkpoints_landed_s: list | None = None
    target_error: dict | None = None
    backward: bool = False
    start_velocity: dict | None = None

    def as_stats(self) -> dict:
        """The record under the keys of the run's ``stats`` (a key that was never set is
        left out, as before: ``kept``, ``carried``, the checkpoints, ``target_error``,
        ``backward``)."""
        found = {"theta": self.theta, "solvability_warning": self.solvability_warning,
                 "least_squares": self.least_squares}
        optional = {"kept": self.kept, "carried": self.carried, "checkpoints": self.checkpoints,
                    "checkpoints_landed_s": self.checkpoints_landed_s,
                    "target_error": self.target_error, "backward": self.backward or None}
        return {**found, **{key: value for key, value in optional.items() if value is not None}}


@dataclass(frozen=True)
class EndsRecord:
    """What a fixed-endpoint solve found (``Solution.ends``; ``solvers/bvp/fixed_ends.py``).

    Attributes:
        stages: the solver runs in order (``Stage``: the first guess's, each continuation's,
            the last solve's), their records as ``meta.json`` keeps them (``phases``).
        action: the discrete action of the point (``nan`` for a point that is not finite).
        p_sign_changes: the sign changes of each momentum along the trajectory (which of the
            solutions through the two ends this one is).
        canonical_limit, energy_limit: the limits of the unscaled residuals.
        canonical_residual_max, energy_residual_max: the largest unscaled residuals (``None``
            for a point that is not finite).
        tau_min: the shortest step (``None`` for a point that is not finite).
    """

    stages: tuple
    action: float
    p_sign_changes: tuple
    canonical_limit: float
    energy_limit: float
    canonical_residual_max: float | None = None
    energy_residual_max: float | None = None
    tau_min: float | None = None

    def as_stats(self, stats: dict) -> dict:
        """The solve's ``stats`` with the record under the keys and in the order the run
        file's ``solver`` has always had."""
        checks = {"canonical_limit": self.canonical_limit, "energy_limit": self.energy_limit}
        if self.tau_min is not None:
            checks.update(canonical_residual_max=self.canonical_residual_max,
                          energy_residual_max=self.energy_residual_max, tau_min=self.tau_min)
        counts = dict(stats)
        first = {"solver": counts.pop("solver"),
                 "phases": [stage.record() for stage in self.stages]}
        first.update((key, counts.pop(key)) for key in ("return_status", "iterations",
                                                        "iterations_total"))
        first["action"] = self.action
        first.update((key, counts.pop(key)) for key in ("energy_scale", "tau_floor"))
        return {**first, "p_sign_changes": list(self.p_sign_changes), **checks, **counts}


@dataclass(frozen=True)
class TransferRecord:
    """What a transfer at a prescribed energy found (``Solution.transfer``;
    ``solvers/bvp/at_energy.py``).

    Attributes:
        transfer_time: ``t_N-1 - t_0``, the time the transfer takes.
        energy: the prescribed energy ``E``.
        residuals: the largest unscaled residual of each kind (``canonical``, ``energy``,
            ``prescribed_energy``, ``q_end``).
        residual_limit: the limit they were verified against.
        tau_min, tau_max: the shortest and longest step.
        exact: the exact flow's shooting from this transfer (its time, the differences in
            time and path, whether it converged), where the point was finite.
        fixed_time_start: the fixed-time solves the transfer started from (their durations
            and the last one's message), where ``solve_bvp`` made them.
    """

    transfer_time: float
    energy: float
    residuals: dict
    residual_limit: float
    tau_min: float
    tau_max: float
    exact: dict | None = None
    fixed_time_start: dict | None = None

    def as_stats(self, stats: dict) -> dict:
        """The solve's ``stats`` with the record under the keys and in the order the run
        file's ``solver`` has always had."""
        found = {"transfer_time": self.transfer_time, "energy": self.energy,
                 "residuals": self.residuals, "limit": self.residual_limit, **stats,
                 "tau_min": self.tau_min, "tau_max": self.tau_max}
        later = {"exact": self.exact, "fixed_time_start": self.fixed_time_start}
        return {**found, **{key: value for key, value in later.items() if value is not None}}


@dataclass(frozen=True)
class HigherRecord:
    """What a solve of a system with higher derivatives found besides its nodes
    (``Solution.higher``; ``solvers/higher``).

    Attributes:
        energy: the discrete energy ``E^(k)`` at each node where the recursion defines it.
        p_defined: the nodes ``[lo, hi)`` where ``p`` (the multiplier ``lambda_1``) is
            defined; the others repeat the nearest defined value.
        stages: a fixed-endpoint solve's solver runs in order (``Stage``), else empty.
        residuals: a fixed-endpoint solve's verified residuals (``euler_lagrange_residual``,
            ``energy_equation_residual``) and their limits, else ``None``.
    """

    energy: np.ndarray
    p_defined: tuple
    stages: tuple = ()
    residuals: dict | None = None


@dataclass
class Solution:
    """Nodes ``t`` (N,), ``q`` and ``p`` (N, n), steps ``tau`` (N-1,) and how the solve went.

    Every accepted node is kept, also when ``status`` is a failure.

    Attributes:
        energy_residual: residual of the energy equation at each interior node (N-2,), in the
            units of ``H`` (``fixed`` steps: the ``lee`` balance they do not enforce).
        canonical_residual: largest canonical residual of each interval (N-1,), increment form.
        newton_iterations: Newton iterations of the march's careful steps (compiled fast steps
            do not report theirs; see ``stats["fast_steps"]``), or the NLP solver's iterations.
        solvability: ``c(z_k) = -(f' H_zz f)/8`` at every node for the energy rules (a positive
            step needs it to keep its sign; docs/theory.md section 7), else empty.
        local_error: the accuracy check's local error of each step (N-1,), ``|z_{k+1} -
            Phi(z_k)|_inf`` against the exact flow (a step its RK4 screen passed carries that
            screen's figure; ``solvers/accuracy/judgement.py``), where it was made.
        timing: ``build_s`` and ``solve_s`` in seconds (wall); a march and a fixed-endpoint
            solve add ``accuracy_s``, the accuracy check's share of ``solve_s`` (and
            ``accuracy_cpu_s``, its CPU time, for the fixed-endpoint solve).
        verdict: the accuracy check's `Verdict` (``solvers/accuracy/judgement.py`` sets it, once,
            in ``judge``), or ``None`` where no check was made (``accuracy=None``, a point that
            is not finite, a stopped long march: ``accuracy_skipped`` says why).
        orbit, march, ends, transfer, higher: what the solve found besides its nodes, typed
            by family (`OrbitRecord`, `MarchRecord`, `EndsRecord`, `TransferRecord`,
            `HigherRecord`); ``None`` for the other families.
        own_residual_max: a compared method's largest residual of its own equation
            (``studies/methods.py``), ``None`` where it has none or was not checked.
        accuracy_skipped: why a march's check was left out, else ``None``.
        stats: the solver's counts (IPOPT's, the march's retries, ...). A march's
            ``fast_steps`` counts the nodes it kept from compiled chunks; ``careful_steps``
            counts the steps tried on the careful path, including one that failed or that a
            monitor then cut (so the two can add up to one more than the steps).
        t_end: the end time the run was asked for (a march's last node lies up to one step past
            it); ``at_end()`` interpolates there.
        vector_field: ``f(t, z) -> z'`` on rows (``(M,)``, ``(M, 2n)``), the exact flow's vector
            field ``(H_p, -H_q)`` of the solved system; set by ``march`` and ``solve_bvp`` for
            ``at`` and ``energy`` (``solvers/dense.py``: it pickles as CasADi's serialization
            of the same function, so a copy in another process gives the same answers).
        t_eval, z_eval: the times a march was asked to report (``Output(t_eval=...)``) up to
            its last node and ``z = (q, p)`` there ``(M, 2n)``, from ``at``; else ``None``.
        t_events, z_events: per event function (``Output(events=...)``), the times ``(K,)``
            and states ``(K, 2n)`` of its crossings, located to round-off on ``at``'s
            interpolant; else ``None``.
        system: the solved system (``energy()`` and ``plot()`` use it); not pickled.
        derivatives: a march's ``d(q, p)(t_eval)`` by input (``march(..., derivatives=...)``:
            ``"q0"``, ``"p0"`` ``(M, 2n, n)``, ``"params"`` ``(M, 2n, m)``); else ``None``.
    """

    t: np.ndarray
    q: np.ndarray
    p: np.ndarray
    status: Status
    message: str
    scheme: str
    energy_residual: np.ndarray
    canonical_residual: np.ndarray
    newton_iterations: int = 0
    solvability: np.ndarray = field(default_factory=lambda: np.zeros(0))
    local_error: np.ndarray = field(default_factory=lambda: np.zeros(0))
    timing: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    verdict: Verdict | None = None
    orbit: OrbitRecord | None = None
    march: MarchRecord | None = None
    ends: EndsRecord | None = None
    transfer: TransferRecord | None = None
    higher: HigherRecord | None = None
    own_residual_max: float | None = None
    accuracy_skipped: str | None = None
    t_end: float | None = None
    vector_field: Callable | None = field(default=None, repr=False, compare=False)
    t_eval: np.ndarray | None = None
    z_eval: np.ndarray | None = None
    t_events: list | None = None
    z_events: list | None = None
    system: object = field(default=None, repr=False, compare=False)
    derivatives: dict | None = field(default=None, repr=False, compare=False)

    @property
    def success(self) -> bool:
        """Reached ``t_end``, or stopped at a terminal event (as scipy's ``solve_ivp``)."""
        return self.status in (Status.SUCCESS, Status.EVENT)

    @property
    def statistics(self) -> SolverStatistics:
        """The solver's counts in named fields (`SolverStatistics`)."""
        return SolverStatistics.of(self)

    def written_stats(self) -> dict:
        """``stats`` with what the solve found (`MarchRecord`, `EndsRecord`, `TransferRecord`)
        under the keys and in the order run files have always used: the one mapping from the
        typed records to those keys."""
        for record in (self.ends, self.transfer):
            if record is not None:
                return record.as_stats(self.stats)
        return {**self.stats, **(self.march.as_stats() if self.march is not None else {})}

    @property
    def tau(self) -> np.ndarray:
        return np.diff(self.t)

    @property
    def steps(self) -> int:
        return max(self.t.size - 1, 0)

    def at(self, t):
        """``(q, p)`` at time ``t`` (a number or an array of shape ``(M,)``) in ``[t_0, t_N-1]``.

        Cubic Hermite interpolation on the interval ``t_k <= t <= t_k+1`` with the node values
        ``z_k``, ``z_k+1`` and the slopes ``f_k = f(t_k, z_k)``, ``f_k+1``
        (``theta = (t - t_k)/tau_k``):

            z(t) = h00 z_k + h10 tau_k f_k + h01 z_k+1 + h11 tau_k f_k+1

        with the Hermite basis ``h00 = 2 theta^3 - 3 theta^2 + 1``, ``h10 = theta^3 - 2 theta^2
        + theta``, ``h01 = 3 theta^2 - 2 theta^3``, ``h11 = theta^3 - theta^2``. The slopes are the
        exact vector field where the solver set ``vector_field``, else second-order finite
        differences of the nodes (``numpy.gradient``). The interpolant's own error is
        ``O(tau^4)``, so between the nodes the error is the scheme's, ``O(tau^2)``, and at a node
        ``at`` returns the node (docs/theory.md section 10).

        Returns:
            ``q``, ``p`` of shape ``(n,)`` for a number ``t``, ``(M, n)`` for an array.

        Raises:
            InputError: a time outside the run's nodes (no extrapolation).
        """
        times = np.asarray(t, dtype=float)
        rows = np.atleast_1d(times)
        if self.t.size == 0:
            raise InputError("the solution has no nodes to interpolate")
        # the end times' round-off, in the run's own units (with a floor of 1, a run 1e-8 long
        # answered for times 1e-4 of its span past its end)
        slack = 1e-12 * max(abs(self.t[0]), abs(self.t[-1]))
        if rows.ndim != 1:
            raise InputError(f"t must be a number or a 1-d array of times, got shape "
                             f"{rows.shape}")
        low, high = min(self.t[0], self.t[-1]), max(self.t[0], self.t[-1])
        outside = ~((rows >= low - slack) & (rows <= high + slack))
        if np.any(outside):
            shown = ", ".join(f"{float(x):.17g}" for x in rows[outside][:3])
            raise InputError(f"t must lie in the run's span [{float(low):.17g}, "
                             f"{float(high):.17g}] (no extrapolation), got {shown}"
                             + (f" and {int(outside.sum()) - 3} more" if outside.sum() > 3
                                else ""))
        z = np.hstack([self.q, self.p])
        if self.t.size == 1:
            values = np.repeat(z, rows.size, axis=0)
        else:  # a backward march's times decrease: the same nodes read in increasing order
            order = slice(None) if self.t[-1] >= self.t[0] else slice(None, None, -1)
            values = hermite(self.t[order], z[order], self._slopes(z)[order],
                             np.clip(rows, low, high))
        n = self.q.shape[1]
        if times.ndim == 0:
            return values[0, :n], values[0, n:]
        return values[:, :n], values[:, n:]

    def at_end(self):
        """``(q, p)`` exactly at the requested ``t_end`` (``at(t_end)``), or at the last node
        if the run did not say what it was asked for or stopped before ``t_end``."""
        end = self.t_end if self.t_end is not None else self.t[-1]
        backward = self.t.size > 1 and self.t[-1] < self.t[0]
        return self.at(max(end, self.t[-1]) if backward else min(end, self.t[-1]))

    def energy(self, system=None, params=None) -> np.ndarray:
        """``H(q_k, p_k, t_k)`` at every node, for the ``system`` that was solved (default: the
        one the solver remembered, or after pickling its dense field's ``H``; ``params``: its
        parameter values; default the values the solve used, ``march.theta``, else the
        system's defaults)."""
        system = system if system is not None else self.system
        if system is None and params is None and hasattr(self.vector_field, "energy"):
            return self.vector_field.energy(self.q, self.p, self.t)
        if system is None:
            raise InputError("energy() needs the solved system: this solution does not hold it "
                             "(pass energy(system))")
        if params is not None or self.march is None:
            theta = system.parameter_vector(params)
        else:
            theta = np.asarray(self.march.theta, dtype=float)
        return system.energy(self.q, self.p, self.t, theta)

    def _slopes(self, z: np.ndarray) -> np.ndarray:
        if self.vector_field is not None:
            return np.asarray(self.vector_field(self.t, z), dtype=float).reshape(z.shape)
        return np.gradient(z, self.t, axis=0)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["system"] = None  # its CasADi functions and scene code stay in this process
        if not getattr(self.vector_field, "portable", False):
            state["vector_field"] = None  # a closure over this process's functions
        return state

    def __repr__(self) -> str:
        return (f"Solution(status={self.status.code}, steps={self.steps}, "
                f"t=[{self.t[0]:.6g}, {self.t[-1]:.6g}], message={self.message!r})")


def hermite(t: np.ndarray, z: np.ndarray, slopes: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation of the rows ``z`` (slopes ``slopes``) at ``times``, on the
    interval ``t_k <= time < t_k+1`` (the last one for the last node)."""
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 2)
    tau = (t[k + 1] - t[k])[:, None]
    theta = ((times - t[k]) / (t[k + 1] - t[k]))[:, None]
    theta2, theta3 = theta**2, theta**3
    return ((2 * theta3 - 3 * theta2 + 1) * z[k] + (theta3 - 2 * theta2 + theta) * tau * slopes[k]
            + (3 * theta2 - 2 * theta3) * z[k + 1] + (theta3 - theta2) * tau * slopes[k + 1])


@dataclass(frozen=True)
class SolverStatistics:
    """A solve's counts by name (``Solution.statistics``; ``Solution.stats`` keeps the full,
    solver-specific dict).

    Attributes:
        steps: accepted steps (intervals) returned.
        newton_iterations: Newton iterations counted by CasADi's careful rootfinder (a march's
            compiled steps do not report theirs) or the NLP solver's iterations.
        function_evaluations: evaluations of the careful step equations (residual with its
            Jacobian): CasADi's ``newton`` evaluates them once before each iteration's test,
            so one more than its iterations per solve: ``newton_iterations + careful_steps +
            retries`` for a march (compiled chunks not counted); ``None`` where nothing
            counted them (the grid solvers).
        fast_steps: a march's steps kept from compiled chunks.
        careful_steps: a march's steps tried on the careful path.
        retries: Newton restarts from a changed predictor (careful march steps).
        least_squares_steps: steps replaced by the least-squares step.
        build_s, solve_s: seconds spent building and solving.
    """

    steps: int
    newton_iterations: int
    function_evaluations: int | None
    fast_steps: int
    careful_steps: int
    retries: int
    least_squares_steps: int
    build_s: float
    solve_s: float

    @classmethod
    def of(cls, solution: Solution) -> SolverStatistics:
        stats, timing = solution.stats, solution.timing
        careful = int(stats.get("careful_steps", 0))
        evaluations = None
        if "careful_steps" in stats:
            evaluations = solution.newton_iterations + careful + int(stats.get("retries", 0))
        return cls(steps=solution.steps, newton_iterations=int(solution.newton_iterations),
                   function_evaluations=None if evaluations is None else int(evaluations),
                   fast_steps=int(stats.get("fast_steps", 0)), careful_steps=careful,
                   retries=int(stats.get("retries", 0)),
                   least_squares_steps=len(solution.march.least_squares) if solution.march else 0,
                   build_s=float(timing.get("build_s", 0.0)),
                   solve_s=float(timing.get("solve_s", 0.0)))

__all__ = ["EndsRecord", "Failure", "HigherRecord", "MarchRecord", "OrbitRecord", "Solution",
           "SolverStatistics", "Status", "TransferRecord", "Verdict", "bound_reached", "hermite"]
