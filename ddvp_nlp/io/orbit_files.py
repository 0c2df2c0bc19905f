"""Writing periodic orbits: a run folder (``result.npz``, ``meta.json``, ``orbit.png``) and a
family (``family.csv``, ``family.png``, one run folder per energy)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..solution import Solution
from . import atomic, figures
from .run_folder import figure_writer

FAMILY_COLUMNS = ("energy", "status", "period", "nodes", "canonical", "energy_equation",
                  "closure", "unfolding", "iterations")


def periodic_meta(scene, solution: Solution, params: dict) -> dict:
    """What ``meta.json`` holds: the orbit's period and energy, the residuals, the status."""
    stats, orbit = solution.stats, solution.orbit
    return {"command": "periodic", "scene": scene.name, "scheme": solution.scheme,
            "status": solution.status.code, "message": solution.message,
            "period": orbit.period, "energy": orbit.energy, "section": orbit.section,
            "nodes": solution.t.size, "params": params, "residuals": orbit.residuals,
            "residual_limit": orbit.residual_limit, "unfolding": orbit.unfolding,
            "integral_unfoldings": list(orbit.integral_unfoldings),
            "solver": stats.get("solver"), "outcome": stats["outcome"],
            "iterations": stats["iterations"], "attempts": stats.get("attempts", []),
            "winding": list(orbit.winding),
            "accuracy": solution.verdict.as_dict() if solution.verdict is not None else {},
            "tau_min": orbit.tau_min, "tau_max": orbit.tau_max,
            "timing": solution.timing}


def write_periodic(out, scene, solution: Solution, params: dict, plot: bool = True, *,
                   interruptible=None):
    """``result.npz`` (``t``, ``q``, ``p`` of the ``N + 1`` nodes, the last equal to the
    first), ``orbit.png`` if ``plot``, and ``meta.json`` last, as one set through the output
    layer (`ddvp_nlp.io.atomic`); returns the meta."""
    meta = periodic_meta(scene, solution, params)

    def draw(handle):
        plot_orbit(solution, f"{scene.name}: E = {meta['energy']:.6g}, "
                             f"T = {meta['period']:.8g} ({meta['status']})", handle)

    def arrays(handle):
        np.savez(handle, t=solution.t, q=solution.q, p=solution.p,
                 canonical_residual=solution.canonical_residual,
                 energy_residual=solution.energy_residual)

    with atomic.output_folder(out) as folder:
        figure = figure_writer(folder, "orbit.png", draw if plot else None, interruptible)
        if plot and figure is None:
            meta["figure"] = "not drawn: interrupted while drawing"
        return folder.commit({"result.npz": arrays, "orbit.png": figure}, meta)


def configuration_curves(solution: Solution):
    """``[(x, y, label), ...]``: the phase plane for one degree of freedom, the plane ``(q1,
    q2)`` for two, and for more (an even number) one curve per body ``(q_{2i+1}, q_{2i+2})``."""
    q, p, n = solution.q, solution.p, solution.q.shape[1]
    if n == 1:
        return [(q[:, 0], p[:, 0], "$(q, p)$")]
    if n == 2 or n % 2:
        return [(q[:, 0], q[:, 1], "$(q_1, q_2)$")]
    return [(q[:, 2 * i], q[:, 2 * i + 1], f"body {i + 1}") for i in range(n // 2)]


def plot_orbit(solution: Solution, title: str, path: Path, fmt: str = "png") -> None:
    """The orbit (``configuration_curves``) with its nodes at equal aspect, and the step
    length along it; a failed solve says so in the title (its nodes are the last iterate)."""
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH, 3.2)
        left, right = fig.subplots(1, 2, width_ratios=[1, 1.3])
        curves = configuration_curves(solution)
        for x, y, label in curves:
            left.plot(x, y, ".-", ms=2, lw=0.7, label=label)
        left.set_aspect("equal", adjustable="datalim")
        left.set_xlabel("$q_1$" if len(curves) > 1 or solution.q.shape[1] > 1 else "$q$")
        left.set_ylabel("$p$" if solution.q.shape[1] == 1 else "$q_2$")
        if len(curves) > 1:
            left.legend(loc="upper right")
        left.set_title("orbit")
        right.plot(solution.t[:-1], np.diff(solution.t), ".-", ms=2, lw=0.7)
        right.set_xlabel("$t_k$")
        right.set_ylabel(r"$\tau_k$")
        right.set_title("step length along the orbit")
        fig.suptitle(title if solution.success else
                     f"{title}: FAILED, the last iterate (not an orbit)")
        figures.save(fig, path, fmt)


def family_row(energy: float, solution: Solution) -> dict:
    orbit = solution.orbit
    residuals = orbit.residuals
    return {"energy": energy, "status": solution.status.code, "period": orbit.period,
            "nodes": solution.t.size, "canonical": residuals["canonical"],
            "energy_equation": residuals["energy"], "closure": residuals["closure"],
            "unfolding": orbit.unfolding, "iterations": solution.stats["iterations"]}


def write_family(out, scene, family: list, params: dict, plot: bool = True,
                 reference=None, folders: bool = True, *, section: str | None = None,
                 interruptible=None) -> list[dict]:
    """``family.csv`` (one row per energy, failed ones included), ``family.png`` (period
    against energy, beside the exact period ``T(E)``) and ``meta.json`` as one set, after, if
    ``folders``, a run folder ``E=<energy>`` each.

    ``reference``: ``T(E)``; by default the one the scene declares for the family through
    ``section`` (``PeriodicSettings.period``, the scene's default section if ``None``), with
    the scene's parameters under ``params``. ``family.csv`` then has the exact period and the
    relative difference ``(T - T_exact) / T_exact`` of every member."""
    reference = reference or scene_period(scene, section, params)
    rows = [family_row(energy, solution) for energy, solution in family]
    columns = FAMILY_COLUMNS
    if reference is not None:
        columns = (*FAMILY_COLUMNS, "exact_period", "relative_difference")
        for row in rows:
            exact = float(reference(row["energy"]))
            row["exact_period"] = exact
            # a failed member's period is its last iterate's, not an orbit's
            row["relative_difference"] = ((row["period"] - exact) / exact
                                          if row["status"] == "success" else float("nan"))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    with atomic.output_folder(out) as folder:
        for energy, solution in family if folders else ():
            with folder.subfolder(f"E={energy:.6g}") as member:
                write_periodic(member, scene, solution, params, plot=False)

        def draw(handle):
            plot_family(rows, f"{scene.name}: period against energy", handle, reference)

        figure = figure_writer(folder, "family.png", draw if plot else None, interruptible)
        folder.commit({"family.csv": atomic.text(buffer.getvalue()), "family.png": figure},
                      {"command": "periodic", "scene": scene.name, "members": len(rows),
                       "succeeded": sum(r["status"] == "success" for r in rows),
                       "params": params, "exact_period": reference is not None})
    return rows


def scene_period(scene, section: str | None, params: dict):
    """The exact ``T(E)`` the scene declares for the family through ``section`` (its default
    section if ``None``), its parameters bound (``params`` over the scene's), else ``None``."""
    settings = getattr(scene, "periodic", None)
    if settings is None:
        return None
    values = {**getattr(scene, "params", {}), **params}
    return settings.exact_period(section or settings.section, values)


def plot_family(rows: list[dict], title: str, path: Path, reference=None,
                fmt: str = "png") -> None:
    """The period against the energy: the discrete orbits as dots, beside the exact period
    ``reference(E)`` where the scene has one (then a lower panel shows the relative
    difference); failed energies as red crosses on the energy axis (their period is the last
    iterate's, not an orbit's)."""
    ok = [r for r in rows if r["status"] == "success"]
    failed = [r for r in rows if r["status"] != "success"]
    with figures.styled():
        fig = figures.new_figure(figures.COLUMN_WIDTH * 1.4, 4.2 if reference else 3.0)
        axes = fig.subplots(2 if reference else 1, 1, sharex=True, squeeze=False,
                            height_ratios=[2.2, 1] if reference else [1])[:, 0]
        ax = axes[0]
        if reference is not None and rows:
            energies = np.linspace(min(r["energy"] for r in rows),
                                   max(r["energy"] for r in rows), 400)
            ax.plot(energies, reference(energies), "-", color="0.45", lw=1.0,
                    label="exact period")
        ax.plot([r["energy"] for r in ok], [r["period"] for r in ok], "o", ms=3.5,
                label=f"discrete, {rows[0]['nodes']} nodes" if rows else "discrete")
        if failed:
            ax.plot([r["energy"] for r in failed], [0.0] * len(failed), **figures.FAILED,
                    transform=ax.get_xaxis_transform(), clip_on=False,
                    label="failed (no orbit)")
        ax.set_ylabel("period $T$")
        ax.set_title(title)
        ax.legend(loc="best")
        if reference is not None and ok:
            e = np.array([r["energy"] for r in ok])
            exact = np.asarray(reference(e), dtype=float)
            axes[1].semilogy(e, figures.positive(np.abs(
                np.array([r["period"] for r in ok]) - exact) / np.abs(exact)), "o-", ms=3)
            axes[1].set_ylabel(r"$|T - T_{\mathrm{exact}}| / T_{\mathrm{exact}}$")
        axes[-1].set_xlabel("energy $E$")
        figures.save(fig, path, fmt)
