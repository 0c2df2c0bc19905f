"""The work-precision figure of ``ddvp compare`` (``work_precision.png``): error against run
time, one panel per error kind, from the rows of the comparison (plain dicts with ``method``,
``status``, ``run_s`` and one column per error kind)."""

from __future__ import annotations

from . import figures

# The axis labels of the figure: what is measured, and that it is absolute (the summary's
# header says against what: the DOP853 reference, the first node's energy).
AXIS_LABELS = {"trajectory_error": r"trajectory error $\max_k |z_k - z_{\mathrm{ref}}(t_k)|$",
               "energy_error": r"energy error $\max_k |H_k - H_0|$ (absolute)"}

# One colour per method for up to a dozen methods (the house cycle, then four of Paul Tol's
# "muted" colours): with the cycle's eight, a ninth method took the first one's colour, and
# its failure crosses could not be told from the first's.
METHOD_COLOURS = ("C0", "C1", "C2", "C3", "C4", "C5", "C6", "C7",
                  "#332288", "#44AA99", "#882255", "#999933")


def plot_work_precision(rows, path, *, title, fmt: str = "png"):
    """Error against run time, one panel per error kind, one legend for both below them
    (never over the data): each method's successful runs as a line; a run that failed before
    ``t_end`` has no error to show (its partial run's error would flatter it) and is marked by
    a cross in its method's colour on the panel's top edge at its run time, named in the
    legend."""
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH, 3.9)
        axes = fig.subplots(1, len(AXIS_LABELS))
        for ax, kind in zip(axes, AXIS_LABELS, strict=True):
            for i, method in enumerate(methods_of(rows)):
                plot_method(ax, rows, method, kind, i)
            ax.set_xlabel("run time [s] (best of repeats, build excluded)")
            ax.set_ylabel(AXIS_LABELS.get(kind, kind))
            ax.grid(True, which="major")
        figure_legend(fig, axes)
        fig.suptitle(title)
        figures.save(fig, path, fmt)


def figure_legend(fig, axes) -> None:
    """One legend for the figure below its panels (outside every panel, so it covers no
    data), each entry once: the methods, then each method's failures."""
    entries = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    if entries:
        labels = sorted(entries, key=lambda label: "failed" in label)
        fig.legend([entries[label] for label in labels], labels, loc="outside lower center",
                   ncol=min(4, len(labels)), fontsize="small")


def plot_method(ax, rows, method, kind, index):
    """One method on one panel: its successful runs as a line, its failures as crosses in
    its colour on the top edge (x: run time; y: the axes' top, not an error), named
    ``METHOD failed`` in the legend."""
    markers = "os^vD<>ph*"
    good = [r for r in rows if r["method"] == method and r["status"] == "success"
            and r[kind] > 0]
    failed = [r for r in rows if r["method"] == method and r["status"] != "success"
              and r["run_s"] > 0]
    colour = METHOD_COLOURS[index % len(METHOD_COLOURS)]
    if good:
        ax.loglog([r["run_s"] for r in good], [r[kind] for r in good],
                  marker=markers[index % len(markers)], label=method, color=colour)
    if failed:
        ax.set_xscale("log")
        ax.plot([r["run_s"] for r in failed], [1.0] * len(failed),
                **{**figures.FAILED, "color": colour}, transform=ax.get_xaxis_transform(),
                clip_on=False, label=f"{method} failed before $t_{{end}}$")


def methods_of(rows) -> list[str]:
    """The methods of the rows, in the order they first appear."""
    return list(dict.fromkeys(r["method"] for r in rows))
