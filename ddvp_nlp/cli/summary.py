"""What a command prints when it is done: the run summary, the accuracy lines, grid counts."""

from __future__ import annotations


def status_summary(command, rows, out, name) -> None:
    from ..studies.stress import status_counts

    print(f"{command}: {len(rows)} runs")
    for method, counts in status_counts(rows).items():
        failed = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "success")
        print(f"  {method:15s} {counts.get('success', 0)} reached t_end"
              + (f"; {failed}" if failed else ""))
    print(f"  written to {out}/ ({name}.csv, {name}.md, {name}.png)")


def print_summary(meta: dict, out) -> None:
    lines = [f"{meta['scene']} {meta['command']} [{meta['scheme']}]: {meta['status']} - "
             f"{meta['message']}",
             f"  steps {meta['steps']}, t reached {meta['t_reached']:.10g}"]
    if meta.get("nodes_kept") is not None:
        every = meta.get("kept_every", 1)
        which = f"every {every}-th and the last" if every > 1 else "the first and the last"
        lines[-1] += f"; {meta['nodes_kept']} nodes kept ({which})"
    if meta.get("tau_min") is not None:
        lines.append(f"  tau in [{meta['tau_min']:.6g}, {meta['tau_max']:.6g}]")
    lines.extend(_accuracy_lines(meta))
    lines.extend(_energy_step_advice(meta))
    if "own_residual_max" in meta:
        own = meta["own_residual_max"]
        lines.append("  own residual check: " + ("none (no equation on its nodes)" if own is None
                                                 else f"largest step residual {own:.3e}"))
    lines.append(f"  scheme's energy residual {meta['energy_error']:.3e} "
                 f"({meta['energy_error_kind']}{_of_energy_scale(meta)})")
    if "solvability_warning" in meta:
        warning = meta["solvability_warning"]
        lines.append(f"  solvability warning at step {warning['step']}, t = {warning['t']:.6g}: "
                     f"{warning['reason']}")
    if "least_squares_steps" in meta:
        lines.append(f"  {meta['least_squares_steps']} least-squares steps, largest energy "
                     f"defect {meta['least_squares_defect_max']:.3e}")
    if "note" in meta:
        lines.append(f"  {meta['note']}")
    if "error_vs_exact" in meta:
        lines.append(f"  error against the exact solution {meta['error_vs_exact']:.3e} "
                     f"(absolute: the largest |z_k - z_exact(t_k)| over the run, in the units "
                     f"of q and p)")
    path = f" ({meta['path']} path)" if "path" in meta else ""
    target = meta.get("target_error")
    if target and target.get("tau0") is None:
        pilot = target["pilot"]
        lines.append(f"  target error {target['target']:g}: no step chosen (the pilot at tau0 "
                     f"{pilot['tau0']:g} did not end in success; no run was made); "
                     f"{target['cpu_s']:.2f} s CPU in all")
    elif target:
        pilot, runs = target["pilot"], target["runs"]
        tries = "; ".join(f"tau0 {r['tau0']:.4g}: {r['verdict']} in {r['steps']} steps, "
                          f"{r['cpu_s']:.2f} s CPU" for r in runs)
        lines.append(f"  target error {target['target']:g}: tau0 {target['tau0']:.4g} chosen "
                     f"from a pilot at tau0 {pilot['tau0']:g} to t = {pilot['t_end']:.6g} "
                     f"(error {pilot['error']:.2e} at t = {pilot['measured_to']:.6g}, growth "
                     f"t^{pilot['growth']:.2f}, predicted {pilot['predicted']:.2e} at t_end at "
                     f"its step; {pilot['cpu_s']:.2f} s CPU); {tries}; "
                     f"{target['cpu_s']:.2f} s CPU in all")
    first = meta.get("first_fallback")
    if first:
        careful, refused = meta["steps"] - meta.get("fast_steps", 0), meta.get("fallbacks", 0)
        lines.append(f"  {careful} of {meta['steps']} steps on the careful path: {refused} "
                     f"compiled step{'s were' if refused != 1 else ' was'} refused, the first "
                     f"at t = {first['t']:.10g}: {first['why']}")
    lines.append(f"  build {meta['timing']['build_s']:.3f} s, solve {meta['timing']['solve_s']:.3f}"
                 f" s{path}; written to {out}/")
    print("\n".join(lines))


def _of_energy_scale(meta: dict) -> str:
    """The scheme's energy residual relative to the check's energy scale E_s, where both are
    known: an absolute 7.7e-23 reads as round-off, but was 4e-4 of a Kepler orbit's energy in
    lengths of 1e-10 (the step's residual tolerance is absolute below unit scale)."""
    scale = (meta.get("accuracy") or {}).get("energy_scale")
    residual = meta.get("energy_error")
    if not isinstance(scale, (int, float)) or not scale > 0 or \
            not isinstance(residual, (int, float)):
        return ""
    return f"; {residual / scale:.1e} of the energy scale E_s"


# The statuses by which an energy rule's step equation can end a march: where its positive root
# is lost (c(z) changes sign, a time-dependent H), which fixed steps do not have
ENERGY_STEP_ENDS = ("no_admissible_step", "newton_failed", "step_ratio", "step_below_min",
                    "residual_too_large")


def _energy_step_advice(meta: dict) -> list[str]:
    """Where a march by an energy rule ended in its step equation, what to try: the rule's
    positive root exists only while c(z) keeps its sign (docs/theory.md, sections 7 and 8);
    fixed steps have no such root to lose."""
    if (meta.get("command") != "march" or meta.get("scheme") not in ("vddvp", "lee")
            or meta.get("status") not in ENERGY_STEP_ENDS
            or "round-off sets the step length" in str(meta.get("message"))):
        return []  # (a step refused for H's round-off says its own cause and remedy)
    return [f"  the {meta['scheme']} step has a positive root only while c(z) = -f.H_zz.f / 8 "
            "keeps its sign along the orbit, and a time-dependent H can drive it to zero "
            "(docs/theory.md, sections 7-8); if that is where this run ended, `--scheme fixed` "
            "marches the system with fixed steps, judged by the same check"]


# The motion's sizes printed one by one up to this many components (a chain's 128 are a range)
SHOWN_SCALES = 8


def _accuracy_lines(meta: dict) -> list[str]:
    """The check that does not trust the scheme, before the scheme's own residual: what it
    measured (relative to the motion's own scales) and its verdict, in words. A run that failed
    (or whose check was not made on the whole run) is never called accurate."""
    accuracy = meta.get("accuracy")
    if not accuracy or accuracy.get("scale") is None:
        return []
    sizes = accuracy["scale"]
    scale = (f"[{', '.join(f'{s:.3g}' for s in sizes)}]" if len(sizes) <= SHOWN_SCALES else
             f"{min(sizes):.3g} .. {max(sizes):.3g} over {len(sizes)} components (meta.json "
             f"has each)")
    energy = accuracy.get("energy_scale")
    lines = [f"  accuracy check against the exact flow ({accuracy['estimate']}); the motion's "
             f"size S = {scale}" + ("" if energy is None else
                                      f", energy scale E_s = {energy:.3g}")]
    steps = (f"    steps: local error <= {accuracy['local_error_max']:.3e} of S (limit "
             f"{accuracy['rtol']:g})")
    if accuracy.get("level") is not None:
        floor = accuracy.get("level_round_off")
        error = accuracy["level_error"]
        # a large constant in H: the two values agree to their round-off, no closer
        measured = (f"below its round-off floor {floor:.1e} of E_s" if floor is not None
                    and error is not None and error <= floor else f"{error:.3e} of E_s")
        steps += (f"; energy level of the first step {accuracy['level']:.10g} against "
                  f"{accuracy['level_reference']:.10g} ({measured}, "
                  f"limit {accuracy['energy_tol']:g})")
    if accuracy.get("energy_drift") is not None:
        steps += f"; nodal energy drift {accuracy['energy_drift']:.3e} of E_s"
    lines.append(steps)
    lines.append("    " + _trajectory_words(accuracy))
    lines.append("    verdict: " + _verdict_words(meta, accuracy))
    return lines


def _trajectory_words(accuracy: dict) -> str:
    """What the trajectory error is, and over which part of the run it was measured."""
    tol = accuracy["global_tol"]
    if accuracy.get("reference_lost") is not None:
        return (f"trajectory error <= {accuracy['error_max']:.3e} of S up to t = "
                f"{accuracy['reference_lost']:.6g}, not measurable past it (the reference's "
                f"own error passed its share of the tolerance: the motion is too sensitive)")
    if accuracy.get("t_drift") is not None:
        if accuracy.get("reference_until") not in (None, accuracy["t_drift"]):
            return (f"trajectory error passes {tol:g} of S at t = {accuracy['t_drift']:.6g}; "
                    f"largest {accuracy['error_max']:.3e} of S, at t = "
                    f"{accuracy['error_max_t']:.6g}, over the whole run")
        return (f"trajectory error passes {tol:g} of S at t = {accuracy['t_drift']:.6g} "
                f"({accuracy['error_max']:.3e} there; the scan stops there, so the error past "
                f"it is not measured)")
    return (f"trajectory error <= {accuracy['error_max']:.3e} of S over the whole run (limit "
            f"{tol:g})")


def _verdict_words(meta: dict, accuracy: dict) -> str:
    from ..solution import Verdict
    from ..solvers import describe

    verdict = accuracy["verdict"]
    if verdict == "inaccurate":
        return f"inaccurate: {describe(Verdict.of(accuracy))}"
    if meta.get("status") not in ("success", "event", "drifted") \
            and not accuracy["steps"]:
        return f"no verdict: the run ended {meta['status']} before its first step"
    if meta.get("status") not in ("success", "event", "drifted"):
        reached = meta.get("t_reached")
        at = "" if reached is None else f" at t = {reached:.6g}"
        return (f"no verdict on the whole run (it ended {meta['status']}{at}); the "
                f"{accuracy['steps']} steps kept up to there are "
                + ("accurate" if verdict == "accurate" else
                   f"drifted from t = {accuracy['t_drift']:.6g}"))
    if verdict == "drifted":
        return (f"drifted from t = {accuracy['t_drift']:.6g}: every step follows the flow and "
                "the energy is right, but the phase is lost"
                + ("" if accuracy.get("require_accurate") else
                   " (exit 0; --require-accurate makes this a failure)"))
    return "accurate"


def format_warning(message, category, filename, lineno, line=None):
    return f"ddvp: warning: {message}\n"
