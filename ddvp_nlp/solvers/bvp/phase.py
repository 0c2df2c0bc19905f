"""One solve of the fixed-endpoint system by one solver: the unit the starts and the final
solve are made of (``bvp.py``, ``bvp_start.py``).

A :class:`Request` holds the validated inputs of ``solve_bvp``; :func:`run_phase` solves the
system of a scheme (the user's, or ``fixed`` on given times for the start) from a point, by
Newton (``bvp_newton.py``) or IPOPT (``bvp_ipopt.py``), and records what the solver said. The
built problems are cached per system (``PROBLEMS``), their build time counted apart.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ...cache import PROBLEMS
from ...discrete import equations
from ...discrete.scheme import Scheme
from ..grid.ipopt import IpoptProblem
from ..grid.newton import newton
from .assembly import Ends, GridAssembly
from .ipopt import AssemblyIpoptProblem

EPS = np.finfo(float).eps
# Newton's target on each row: this many units of the row's round-off (module docstring of
# bvp_newton.py); verification allows ROUND_OFF_ALLOWANCE of them (bvp.py).
TARGET_ULPS = 16
ROUND_OFF_ALLOWANCE = 1024
# How the IPOPT problem is built: "assembly" (callbacks on the banded assembly,
# bvp_ipopt_assembly.py) or "mx" (an MX NLP of mapped per-interval functions, bvp_ipopt.py).
# Measured side by side in scripts/bench_bvp.py, which sets this per run.
IPOPT_BUILDS = {"assembly": AssemblyIpoptProblem, "mx": IpoptProblem}
IPOPT_BUILD = "assembly"


@dataclass
class Request:
    """The validated inputs of one ``solve_bvp`` call."""

    system: object
    scheme: Scheme
    nodes: int
    q_start: np.ndarray
    q_end: np.ndarray
    t0: float
    t1: float
    grid_times: np.ndarray
    theta: np.ndarray
    tol: float
    tau_floor: float
    solver: str
    max_iter: int
    verbose: bool = False
    linear: str = "auto"
    deadline: float | None = None
    progress: bool = False
    p_start: np.ndarray | None = None
    build_s: float = 0.0
    phases: list = field(default_factory=list)

    @property
    def mean_step(self) -> float:
        return (self.t1 - self.t0) / (self.nodes - 1)

    def ends(self, scheme: Scheme, times=None) -> Ends:
        """The data of the system of ``scheme``: for ``fixed``, on ``times`` (default the
        request's grid)."""
        if scheme.variable_steps:
            return Ends(self.q_start, self.q_end, np.array([self.t0, self.t1]), self.theta,
                        self.mean_step)
        return Ends(self.q_start, self.q_end,
                    self.grid_times if times is None else np.asarray(times, float),
                    self.theta, 1.0)

    def remaining(self) -> float | None:
        return None if self.deadline is None else max(self.deadline - time.perf_counter(), 0.0)


def assembly(request: Request, scheme: Scheme) -> GridAssembly:
    return built(request, ("bvp_assembly", scheme, request.nodes),
                  lambda: GridAssembly(request.system, scheme, request.nodes))


def built(request, key, build):
    """``build()`` cached per system under ``key`` (``PROBLEMS``), its time added to
    ``request.build_s`` (any request with ``system`` and ``build_s``: the higher-order solver's
    too)."""
    started = time.perf_counter()
    value = PROBLEMS.get(request.system, key, build)
    request.build_s += time.perf_counter() - started
    return value


def round_off_scales(request: Request, x: np.ndarray, scheme: Scheme):
    """``(canonical, energy)``: the magnitude whose round-off bounds a canonical row
    (``max(1, |q|, |p|, |t|)``) and an unscaled energy row (``max(1, |E_k|)`` on up to 1000
    sampled intervals)."""
    m = 2 * request.system.n + 1
    z = x.reshape(-1, m)
    canonical = float(max(1.0, np.max(np.abs(z))))
    if not scheme.variable_steps:
        return canonical, 1.0
    k = np.unique(np.linspace(0, request.nodes - 2, min(request.nodes - 1, 1000)).astype(int))
    n = request.system.n
    E = equations.interval_energies(request.system, scheme, z[np.r_[k, k[-1] + 1], 0],
                                    z[np.r_[k, k[-1] + 1], 1:n + 1],
                                    z[np.r_[k, k[-1] + 1], n + 1:], request.theta)
    return canonical, float(max(1.0, np.max(np.abs(E[:-1]))) if E.size > 1 else 1.0)


def newton_targets(request: Request, grid: GridAssembly, x, ends: Ends) -> np.ndarray:
    """Per-row ``|F_i|`` targets: ``TARGET_ULPS`` round-offs of each row (the energy rows in
    their scaled units)."""
    n, N, m = request.system.n, request.nodes, 2 * request.system.n + 1
    canonical, energy = round_off_scales(request, x, grid.scheme)
    target = np.full(N * m, TARGET_ULPS * EPS * canonical)
    body = target[n + 1:n + 1 + (N - 1) * m].reshape(N - 1, m)
    if grid.scheme.variable_steps:
        body[:-1, 2 * n] = TARGET_ULPS * EPS * energy / ends.energy_scale
    return target


def run_phase(request: Request, scheme: Scheme, x0: np.ndarray, name: str, solver: str,
              times=None):
    """``(x, phase)``: the system of ``scheme`` solved from ``x0`` by ``solver``; ``phase``
    records the solver's own verdict (``converged``, ``return_status``, ``iterations``)."""
    ends = request.ends(scheme, times)
    started = time.perf_counter()
    if solver == "newton":
        grid = assembly(request, scheme)
        result = newton(grid, x0, ends, newton_targets(request, grid, x0, ends),
                        tau_floor=request.tau_floor if scheme.variable_steps else -np.inf,
                        max_iter=request.max_iter, linear=request.linear,
                        deadline=request.deadline,
                        progress=_reporter(name) if request.progress else None)
        x, converged, said, iterations = (result.x, result.converged, result.outcome,
                                          result.iterations)
    else:
        remaining = request.remaining()
        build = IPOPT_BUILDS[IPOPT_BUILD]
        problem = built(request, ("bvp_ipopt", IPOPT_BUILD, scheme, request.nodes,
                                   request.max_iter, request.tol, request.verbose, remaining),
                         lambda: build(request.system, scheme, request.nodes, tol=request.tol,
                                       max_iter=request.max_iter,
                                       verbose=request.verbose or request.progress,
                                       time_limit=remaining))
        x, converged, said, iterations = problem.solve(x0, ends, request.tau_floor)
    phase = {"phase": name, "solver": solver, "converged": converged, "return_status": said,
             "iterations": iterations, "seconds": time.perf_counter() - started}
    request.phases.append(phase)
    return x, phase


def _reporter(name: str):
    def report(iteration, norm, alpha):
        print(f"bvp [{name}]: iteration {iteration}, |F| = {norm:.3e}, step {alpha:.3g}",
              file=sys.stderr, flush=True)
    return report
