"""The figures of ``ddvp reproduce``: the paper's figures 1-3 redrawn from the measured run, the
site density's spread against the step, and the step-ratio sweep."""

from __future__ import annotations

from . import figures


def reproduce_figures(example, site, sweep) -> dict:
    """The report's figures, as writers of the output layer (name -> ``writer(file)``)."""
    return {"paper_figures.png": lambda handle: _paper_figures(handle, example),
            "site_density.png": lambda handle: _site_figure(handle, site),
            "step_ratios.png": lambda handle: _ratio_figure(handle, sweep)}


def _paper_figures(path, example):
    """The paper's figures 1-3 redrawn from the measured run: the step length over the whole
    run (as its min/max envelope) and over ``t <= 350``, the angle and the step over
    ``t <= 16``, node by node."""
    solution = example["solution"]
    t, q, tau = solution.t, solution.q[:, 0], solution.tau
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH * 0.8, 6.6)
        axes = fig.subplots(4, 1)
        for ax, t_max, title in ((axes[0], t[-1], "figure 1"), (axes[1], 350.0, "figure 2")):
            sel = t[:-1] <= t_max
            figures.envelope_band(ax, t[:-1][sel], tau[sel], figures.bins_for(ax), lw=0.6)
            ax.set_ylabel(r"$\tau_k$")
            ax.set_title(f"{title}: step length against time, $0 \\leq t \\leq {t_max:.0f}$")
        sel = t <= 16.0
        axes[2].plot(t[sel], q[sel], "o-", ms=2.5)
        axes[2].set_ylabel(r"$\theta_k$")
        axes[2].set_title(r"figure 3: angle and step length, $0 \leq t \leq 16$")
        axes[3].plot(t[:-1][sel[:-1]], tau[sel[:-1]], "o-", ms=2.5, color="C1")
        axes[3].set_ylabel(r"$\tau_k$")
        axes[3].set_xlabel("$t$")
        figures.save(fig, path)


def _site_figure(path, site):
    with figures.styled():
        fig = figures.new_figure(figures.COLUMN_WIDTH * 1.4, 3.4)
        ax = fig.subplots()
        for name, data in site.items():
            for key, style in (("node", "o-"), ("midpoint", "s--")):
                ax.loglog(data["tau0"], data[key], style,
                          label=f"{name}, weight at the {key} "
                                f"(slope {data[f'slope_{key}']:.2f})")
        _finish(ax, r"$\max/\min - 1$ of $\tau_k\,(V'' p^2 + V'^2)^{1/3}$",
                "site density (section 4)")
        figures.save(fig, path)


def _ratio_figure(path, sweep):
    with figures.styled():
        fig = figures.new_figure(figures.COLUMN_WIDTH * 1.4, 3.4)
        ax = fig.subplots()
        for rule, color in (("vddvp", "C0"), ("lee", "C1")):
            rows = [r for r in sweep["rows"] if r["rule"] == rule]
            tau0 = [r["tau0"] for r in rows]
            ax.loglog(tau0, [r["ratio_min"] for r in rows], "v-", color=color,
                      label=f"{rule}: min")
            ax.loglog(tau0, [r["ratio_max"] for r in rows], "^-", color=color,
                      label=f"{rule}: max")
        _finish(ax, r"$\tau_k / \tau_0$",
                "paper's example to $t = 16$: range of the steps (section 4)")
        figures.save(fig, path)


def _finish(ax, ylabel, title):
    """Labels, legend and grid of a log-log panel against tau0."""
    ax.set_xlabel(r"$\tau_0$")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize="small")
    ax.grid(True, which="major")
