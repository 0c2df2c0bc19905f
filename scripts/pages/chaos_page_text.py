"""The figures and the text of docs/chaos/README.md from the work folder of
scripts/pages/chaos_page.py (imported by its ``page`` stage; nothing is run here)."""

from __future__ import annotations

import json
import platform
from pathlib import Path

import numpy as np

CAP = 8.0


def _load(path: Path) -> dict:
    with np.load(path) as data:
        return {key: data[key] for key in data.files}


def _panel(ax, chaos, values, title, matplotlib):
    M, N = (int(v) for v in chaos["shape"])
    x, y = chaos["axis_0"], chaos["axis_1"]
    cmap = matplotlib.colormaps["magma"].with_extremes(bad="#dddddd")
    dx, dy = (x[1] - x[0]) / 2, (y[1] - y[0]) / 2
    image = ax.imshow(np.ma.masked_invalid(values.reshape(M, N)), origin="lower", cmap=cmap,
                      vmin=0, vmax=CAP, extent=(x[0] - dx, x[-1] + dx, y[0] - dy, y[-1] + dy),
                      interpolation="nearest")
    ax.contour(chaos["boundary_0"], chaos["boundary_1"], chaos["boundary_H"],
               levels=[float(chaos["energy"])], colors="#1f77b4", linewidths=0.8)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("$q_2$")
    return image


def figure(chaos: dict, exact: dict, threshold: float, target: Path, label: str) -> None:
    """Discrete map | exact map | where they differ (class at T), unstable cells marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(11.5, 3.9), constrained_layout=True)
    T = float(chaos["t_end"])
    image = _panel(axes[0], chaos, chaos["megno"],
                   f"march + tangent ($\\tau_0$ = {float(chaos['tau0']):g})", matplotlib)
    _panel(axes[1], chaos, exact["megno"], "exact flow (DOP853, rtol 1e-12)", matplotlib)
    run = chaos["status"] == "success"
    cd, ce = chaos["megno"] > threshold, exact["megno"] > threshold
    stable = run & (cd == (chaos["megno_half"] > threshold)) & \
        (ce == (exact["megno_half"] > threshold))
    code = np.full(cd.shape, np.nan)
    code[run] = 0.0
    code[run & ~stable] = 1.0
    code[run & (cd != ce)] = 2.0
    M, N = (int(v) for v in chaos["shape"])
    x, y = chaos["axis_0"], chaos["axis_1"]
    dx, dy = (x[1] - x[0]) / 2, (y[1] - y[0]) / 2
    colours = matplotlib.colors.ListedColormap(["#f2f2f2", "#9ecae1", "#d62728"]) \
        .with_extremes(bad="#ffffff")
    axes[2].imshow(np.ma.masked_invalid(code.reshape(M, N)), origin="lower", cmap=colours,
                   vmin=-0.5, vmax=2.5, extent=(x[0] - dx, x[-1] + dx, y[0] - dy, y[-1] + dy),
                   interpolation="nearest")
    axes[2].contour(chaos["boundary_0"], chaos["boundary_1"], chaos["boundary_H"],
                    levels=[float(chaos["energy"])], colors="#1f77b4", linewidths=0.8)
    axes[2].set_title(f"classes at $\\langle Y\\rangle$ = {threshold:g}: red differ at T, "
                      "blue\nchange between T/2 and T in either map", fontsize=9)
    axes[2].set_xlabel("$q_2$")
    axes[0].set_ylabel("$p_2$")
    bar = fig.colorbar(image, ax=axes[:2], shrink=0.85, extend="max")
    bar.set_label(f"$\\langle Y\\rangle$ at t = {T:g} (capped at {CAP:g})")
    fig.suptitle(f"{label}: MEGNO over the section $q_1 = 0$, {M} x {N} cells", fontsize=10)
    fig.savefig(target, dpi=130)
    plt.close(fig)


def order(tau, error) -> float:
    """The slope of log |error| against log tau0 (least squares)."""
    tau, error = np.asarray(tau, float), np.abs(np.asarray(error, float))
    keep = error > 0
    return float(np.polyfit(np.log(tau[keep]), np.log(error[keep]), 1)[0])


def _cost_lines(work: Path) -> list[str]:
    cost = json.loads((work / "cost.json").read_text())
    rows = cost["rows"]
    march_cpu = np.array([r["march_cpu"] for r in rows])
    chaos_cpu = np.array([r["chaos_cpu"] for r in rows])
    march_wall = np.array([r["march_wall"] for r in rows])
    chaos_wall = np.array([r["chaos_wall"] for r in rows])
    steps = np.array([r["steps"] for r in rows])
    ratio = chaos_cpu / march_cpu
    return [
        f"{len(rows)} cells (every 200th of the map), one after the other in one process, "
        f"{steps.mean():.0f} steps a cell on average; load average "
        f"{cost['load_before'][0]:.2f} before, {cost['load_after'][0]:.2f} after "
        "(2 cores, shared with other work).",
        "",
        "| per cell | CPU (ms) | wall (ms) | us per step (CPU) |",
        "|---|---|---|---|",
        f"| `march` (compiled, `accuracy=None`) | {1e3 * march_cpu.mean():.1f} | "
        f"{1e3 * march_wall.mean():.1f} | {1e6 * march_cpu.sum() / steps.sum():.3f} |",
        f"| `chaos_indicators` (march + 1 tangent) | {1e3 * chaos_cpu.mean():.1f} | "
        f"{1e3 * chaos_wall.mean():.1f} | {1e6 * chaos_cpu.sum() / steps.sum():.3f} |",
        "",
        f"Cost of a cell against a plain march: **{chaos_cpu.sum() / march_cpu.sum():.2f}x "
        f"CPU** (per cell {ratio.min():.2f}-{ratio.max():.2f}x), "
        f"{chaos_wall.sum() / march_wall.sum():.2f}x wall (target <= 3x). The plain march "
        "also recomputes every equation on its finished grid (its `verify_s`), which a cell "
        "does not; the tangent itself adds one solve with the step's Jacobian per step.",
    ]


def _agreement_lines(a: dict, label: str) -> list[str]:
    thresholds = ", ".join(f"{t}: {100 * v:.1f}%" for t, v in a["thresholds"].items())
    return [
        f"| {label} | {a['run']} | {a['stable']} ({100 * a['stable'] / a['run']:.1f}%) | "
        f"**{100 * a['share_stable']:.2f}%** ({a['stable'] - a['alike_stable']} differ) | "
        f"{100 * a['share_all']:.2f}% ({a['run'] - a['alike_all']} differ) | "
        f"{a['chaotic_discrete']} / {a['chaotic_exact']} | {thresholds} |"]


def write(work: Path, docs: Path, agreement) -> None:
    docs.mkdir(parents=True, exist_ok=True)
    chaos = _load(work / "hh-map" / "chaos.npz")
    exact = _load(work / "hh-exact.npz")
    second = _load(work / "maps" / "hh-E0.1" / "chaos.npz")
    second_exact = _load(work / "second-exact.npz")
    figure(chaos, exact, 2.5, docs / "henon_heiles_E0.125.png", "Henon-Heiles E = 1/8")
    figure(second, second_exact, 2.5, docs / "henon_heiles_E0.1.png", "Henon-Heiles E = 1/10")
    a, b = agreement(chaos, exact), agreement(second, second_exact)
    maps = json.loads((work / "hh-map.json").read_text())
    validate = json.loads((work / "validate.json").read_text())
    shards = json.loads((work / "second.json").read_text())
    T = float(chaos["t_end"])
    lines = _head(T, maps, exact, chaos)
    lines += ["| map | cells run | stable in time | alike, stable cells | alike, all cells | "
              "chaotic (march / exact) | alike at other thresholds (all cells) |",
              "|---|---|---|---|---|---|---|"]
    lines += _agreement_lines(a, "E = 1/8, 100 x 100")
    lines += _agreement_lines(b, "E = 1/10, 40 x 40 (shards)")
    lines += ["", "![E = 1/8](henon_heiles_E0.125.png)", "", "## Cost per cell", ""]
    lines += _cost_lines(work)
    lines += _validation_lines(validate)
    lines += _second_lines(shards, b)
    lines += _tail()
    text = "\n".join(lines) + "\n"
    # <Y> would be read as an HTML tag, and | splits a table's cell
    text = text.replace("`<Y>`", "⟨Y⟩").replace("<Y>", "⟨Y⟩").replace("ln|w|", "ln‖w‖")
    (docs / "README.md").write_text(text)


def _head(T, maps, exact, chaos) -> list[str]:
    run = int(np.sum(chaos["status"] == "success"))
    return [
        "# Chaos maps on the energy-determined tangent map",
        "",
        "Generated by `python scripts/pages/chaos_page.py` (issue 41); every number below is from "
        f"that run ({platform.machine()}, Python {platform.python_version()}). MEGNO "
        "`<Y>`, the fast Lyapunov indicator and the largest exponent are computed on the "
        "march's own tangent map, carried in the compiled chunk: the node times are unknowns "
        "of the energy equation, so a start perturbation also moves the steps, and the tangent "
        "includes the step length's variation by implicit differentiation "
        "(`ddvp_nlp/solvers/chaos/tangent.py`). The tangent never moves a node (the nodes "
        "are `march`'s bit for bit, tested). The tangent's length is measured in weighted "
        "coordinates, each pair $(q_i, p_i)$ scaled by $(a_i, 1/a_i)$ from the flow at the "
        "start (`physics.hamiltonian.symplectic_weights`: a symplectic scaling, so the "
        "exponents still pair), so no indicator depends on the units of a coordinate or of "
        "time or on where the origin is; the plain length put $\\ln 10^5$ on a Henon-Heiles "
        "orbit's FLI in time units of $10^5$ (tested). The derivations are the module "
        "docstrings of `solvers/chaos/` (tangent map, synchronous observation, MEGNO "
        "weights, level map, symplectic flag); the reference is the same indicators "
        "integrated on the exact flow "
        "(`exact_indicators`, `exact_spectrum`: adaptive DOP853 at rtol 1e-12 with the "
        "variational equations and the MEGNO integrals under its error control).",
        "",
        "## The Henon-Heiles map at E = 1/8 against the exact flow",
        "",
        "```bash",
        "ddvp chaos henon_heiles --energy 0.125 --section q1=0 \\",
        f"    --grid 'q2=-0.45:0.7:100,p2=-0.52:0.52:100' --t-end {T:g} --workers 2 --out DIR",
        "```",
        "",
        f"{run} of 10000 cells lie on the energy surface; {maps['wall_s']:.0f} s wall, "
        f"{maps['cpu_s']:.0f} s CPU (the command and its two workers; load average "
        f"{maps['load_before'][0]:.1f} before, {maps['load_after'][0]:.1f} after, on 2 cores "
        f"shared with other work). The exact map: {float(np.nansum(exact['cpu_s'])):.0f} s CPU "
        f"in two processes, {float(exact['wall_s']):.0f} s wall.",
        "",
        f"A cell is *chaotic* when `<Y>` > 2.5 (tori tend to 2, chaotic orbits grow like "
        f"`lambda t / 2`, about {0.045 * T / 2:.0f} here). Its class is *stable in time* when "
        f"it is the same at T/2 = {T / 2:g} and T = {T:g} in both maps: a cell whose class "
        "changes between the two times in either map (a sticky orbit near an island, a slowly "
        "converging torus) has no class yet at this T, and neither map can be wrong about it. "
        "The target (>= 99% alike) is on the stable cells; the share over all cells is given "
        "beside it.",
        "",
    ]


def _validation_lines(v: dict) -> list[str]:
    lines = ["", "## Validation against the exact flow", "",
             "Henon-Heiles E = 1/8, tau0 = 0.02 unless said; `python scripts/pages/chaos_page.py "
             "--stage validate`.", "", "### Regular tori to t = 1e4", "",
             "| (q2, p2) | <Y> march, t = 1e4 | <Y> exact | difference | at t = 2000 "
             "(march / exact) |",
             "|---|---|---|---|---|"]
    for r in v["tori"]:
        lines.append(f"| ({r['q2']}, {r['p2']}) | {r['discrete']:.4f} | {r['exact']:.4f} | "
                     f"{r['discrete'] - r['exact']:+.1e} | {r['discrete_2000']:.4f} / "
                     f"{r['exact_2000']:.4f} |")
    near = [r for r in v["tori"] if abs(r["exact"] - 2) < 0.05]
    ok = [r for r in near if abs(r["discrete"] - 2) < 0.05]
    tori = [r for r in v["tori"] if r["exact"] < 2.5]
    lines += ["", f"Eight starts on the section, five of them tori (exact <Y> < 2.5 at t = 1e4) "
              f"and three chaotic. {len(near)} of the {len(tori)} tori have |<Y> - 2| < 0.05 on "
              f"the exact flow at t = 1e4, and the march gives |<Y> - 2| < 0.05 on {len(ok)} of "
              "them; on every torus the march's <Y> is within "
              f"{max(abs(r['discrete'] - r['exact']) for r in tori):.1e} of the exact flow's "
              "(the other two tori are still converging to 2 on the exact flow too: their "
              "<Y> rose from about 1.7-1.8 at t = 2000). On the chaotic starts both grow like "
              "lambda t / 2; the two chaotic orbits part after a few Lyapunov times, so their "
              "values differ.", "",
              "### Spectra to t = 1e4", "",
              "| orbit | map | exponents (column order) | pair sums | CPU s |",
              "|---|---|---|---|---|"]
    for s in v["spectra"]:
        kind = s["kind"] + (f", tau0 = {s['tau0']}" if "tau0" in s else "")
        lines.append(f"| {s['orbit']} | {kind} | "
                     + ", ".join(f"{e:+.3e}" for e in s["exponents"]) + " | "
                     + ", ".join(f"{e:.1e}" for e in s["pair_sums"]) + f" | {s['cpu_s']:.1f} |")
    worst = max(abs(x) for s in v["spectra"] for x in s["pair_sums"])
    lines += ["", f"Largest pair sum: {worst:.1e} (target 1e-4). The level map's columns are "
              "(reduced, trivial, trivial, reduced): the symplectic flag keeps the pairs exact "
              "at every t; the exact flow's are (trivial, reduced, reduced, trivial), the flow "
              "and the energy surface re-imposed every time unit.", "",
              "### Convergence in tau0", "",
              "Error against the exact flow at the same time (the march's node at or past t):",
              "", "| orbit, t | tau0 | <Y> error | ln|w| error |", "|---|---|---|---|"]
    for name, c in v["convergence"].items():
        for r in c["rows"]:
            lines.append(f"| {name}, {c['t']:g} | {r['tau0']} | {r['megno_error']:+.2e} | "
                         f"{r['log_norm_error']:+.2e} |")
    lines.append("")
    for name, c in v["convergence"].items():
        tau = [r["tau0"] for r in c["rows"]]
        lines.append(f"- {name} (t = {c['t']:g}): fitted order "
                     f"{order(tau, [r['megno_error'] for r in c['rows']]):.2f} for <Y>, "
                     f"{order(tau, [r['log_norm_error'] for r in c['rows']]):.2f} for ln|w|.")
    return lines


def _second_lines(shards: list, b: dict) -> list[str]:
    lines = ["", "## A second map, run as a SLURM-style job array: E = 1/10", "",
             "Henon-Heiles at E = 1/10 on a 40 x 40 grid with other bounds, run as three "
             "shards one after the other here (what `docs/chaos/chaos_array.sbatch` runs as "
             "array tasks 1-3 on a cluster), merged, and compared with the exact flow as above "
             "(table at the top).", "", "```text"]
    for entry in shards:
        lines.append(("$ ddvp chaos --merge maps/hh-E0.1" if entry.get("merge") else
                      f"$ SLURM_ARRAY_TASK_ID={entry['shard']} bash "
                      "docs/chaos/chaos_array.sbatch") + f"   # {entry['wall_s']:.1f} s wall")
        lines += [line for line in entry["stdout"].splitlines()]
    lines += ["```", "", "![E = 1/10](henon_heiles_E0.1.png)"]
    return lines


def _tail() -> list[str]:
    return ["", "## On a cluster", "",
            "- With a Dask scheduler: `ddvp chaos ... --scheduler tcp://host:8786` or "
            "`--cluster slurm:cores=...,memory=...,walltime=...,jobs=J` (the blocks of 25 cells "
            "are tasks; each worker loads the scene and its compiled chunk once).",
            "- Without one (the common SLURM case): a job array, one shard per array task, "
            "each writing `DIR/shard-K-of-N/` with its own lock, journal and `part.npz`; then "
            "`ddvp chaos --merge DIR` once all are done. `docs/chaos/chaos_array.sbatch`:", "",
            "```bash", (Path(__file__).resolve().parents[2] / "docs" / "chaos" /
                        "chaos_array.sbatch").read_text().rstrip(), "```", "",
            "A killed shard (or map) run again with the same command goes on from its "
            "journal (`cells.partial.csv`): only the blocks not yet written run again "
            "(tested with SIGKILL).", ""]
