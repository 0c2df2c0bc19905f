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
    if meta.get("tau_min") is not None:
        lines.append(f"  tau in [{meta['tau_min']:.6g}, {meta['tau_max']:.6g}]")
    lines.extend(_accuracy_lines(meta))
    if "own_residual_max" in meta:
        own = meta["own_residual_max"]
        lines.append("  own residual check: " + ("none (no equation on its nodes)" if own is None
                                                 else f"largest step residual {own:.3e}"))
    lines.append(f"  scheme's energy residual {meta['energy_error']:.3e} "
                 f"({meta['energy_error_kind']})")
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
                     f"(largest over the run)")
    path = f" ({meta['path']} path)" if "path" in meta else ""
    lines.append(f"  build {meta['timing']['build_s']:.3f} s, solve {meta['timing']['solve_s']:.3f}"
                 f" s{path}; written to {out}/")
    print("\n".join(lines))


def _accuracy_lines(meta: dict) -> list[str]:
    """The estimates that do not trust the scheme, before the scheme's own residual."""
    accuracy = meta.get("accuracy")
    if not accuracy:
        return []
    lines = []
    if "node_energy_error" in meta:
        lines.append(f"  energy error {meta['node_energy_error']:.3e} (largest |H(z_k) - H0| / "
                     "max(1, |H0|) at the nodes)")
    if accuracy.get("level") is not None and "H0" in meta:  # H0: not for an interrupted run
        lines.append(f"  energy level of the first step {accuracy['level']:.10g} against "
                     f"H0 = {meta['H0']:.10g} (error {accuracy['level_error']:.3e} of "
                     "max(1, |H0|))")
    estimate = f"{accuracy['global_error_estimate']:.3e} at the end"
    if accuracy.get("global_error_saturated"):
        estimate = (f">= {accuracy['global_error_estimate']:.3g} at the end (as large as the "
                    "orbit: the phase is lost over this horizon; checked only with --global-tol)")
    lines.append(f"  estimated error (against the exact flow): local <= "
                 f"{accuracy['local_error_max']:.3e} per step, global {estimate}; "
                 f"{_verdict_words(accuracy)}")
    return lines


# A global error estimate past this fraction of the orbit's size is called out even when no
# --global-tol bounds it (a harmonic run to t = 20000 at tau = 0.1 printed "accurate" with an
# estimate of 1.8 and a true error of 2.0, the whole orbit).
PHASE_WARNING = 0.1


def _verdict_words(accuracy: dict) -> str:
    """The verdict, saying what it covers: the steps (local error, energy) always, the global
    error only when ``--global-tol`` bounded it."""
    if accuracy["verdict"] != "accurate":
        return accuracy["verdict"]
    if accuracy.get("global_tol") is not None:
        return "accurate (global estimate within --global-tol)"
    if accuracy.get("global_error_saturated"):  # the estimate's own words say the rest
        return "each step accurate"
    size = accuracy.get("orbit_size") or 1.0
    relative = accuracy["global_error_estimate"] / size
    if relative >= PHASE_WARNING:
        state = "the phase is lost" if relative >= 1 else "the phase has drifted"
        return (f"each step accurate, but {state}: the global estimate is {relative:.2g} times "
                f"the orbit's size (not checked unless --global-tol is given)")
    return "accurate"


def format_warning(message, category, filename, lineno, line=None):
    return f"ddvp: warning: {message}\n"
