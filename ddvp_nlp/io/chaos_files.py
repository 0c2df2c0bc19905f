"""``ddvp chaos``'s files: ``chaos.npz`` (every cell's start and indicators), ``chaos.png`` (the
MEGNO map) and, for a shard, ``part.npz`` (the same arrays, the other shards' cells marked
``other_shard``).

``chaos.npz``: ``q0`` and ``p0`` ``(cells, 2)`` (NaN momentum where the cell is outside the
energy surface), ``megno``, ``lyapunov``, ``fli`` and the same at ``t_end / 2``
(``megno_half``, ``lyapunov_half``), ``t`` (the last node's time), ``steps`` and ``status``
``(cells,)`` (``success``, a march's failure code, ``not_run`` outside the energy surface);
the grid: ``axis_names`` (2,), ``axis_0``, ``axis_1`` (the first axis fastest: cell
``j * N + i``), ``shape`` ``(M, N)``; ``energy``, ``t_end``, ``tau0``, ``section``; and the
energy boundary on a fine grid of the axes (``boundary_0``, ``boundary_1``, ``boundary_H``:
the least ``H`` over the section's momentum, the surface ``H = E`` meets the plane where it
equals ``E``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import figures

# The colour scale's cap: <Y> = 2 on tori, larger on chaotic orbits (~ lambda t / 2, hundreds
# at t = 1000); capped so that the tori's structure shows.
MEGNO_CAP = 8.0


def arrays_writer(arrays: dict):
    """A writer of ``arrays`` as one ``.npz`` (strings as fixed-width unicode)."""
    def write(handle):
        np.savez(handle, **{k: np.asarray(v) for k, v in arrays.items()})
    return write


def read_arrays(path) -> dict:
    """The arrays of a ``chaos.npz`` or ``part.npz`` (no pickled objects)."""
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def plot_chaos(arrays: dict, path: Path, fmt: str = "png", *, title: str | None = None,
               ax=None) -> None:
    """The MEGNO map: ``<Y>`` of every cell, the colour scale capped at `MEGNO_CAP`, cells
    outside the energy surface blank, failed cells crossed, the energy boundary drawn."""
    import matplotlib

    with figures.styled():
        own = ax is None
        if own:
            fig = figures.new_figure(figures.COLUMN_WIDTH * 1.45, figures.COLUMN_WIDTH * 1.2)
            ax = fig.subplots()
        image = draw_map(ax, arrays, matplotlib)
        names = [str(name) for name in arrays["axis_names"]]
        ax.set_xlabel(f"${names[0][0]}_{names[0][1:]}$")
        ax.set_ylabel(f"${names[1][0]}_{names[1][1:]}$")
        if title is None:
            run = int(np.sum(arrays["status"] != "not_run"))
            title = (f"MEGNO $\\langle Y\\rangle$ at $t = {float(arrays['t_end']):g}$, "
                     f"$E = {float(arrays['energy']):g}$, ${_tex(str(arrays['section']))}$\n"
                     f"{run} of {arrays['status'].size} cells on the energy surface, "
                     f"$\\tau_0 = {float(arrays['tau0']):g}$")
        ax.set_title(title)
        if own:
            bar = fig.colorbar(image, ax=ax, extend="max", shrink=0.9)
            bar.set_label(f"$\\langle Y\\rangle$ (capped at {MEGNO_CAP:g}; 2: torus)")
            figures.save(fig, path, fmt)
    return image


def draw_map(ax, arrays: dict, matplotlib):
    """The map, the boundary and the failed cells on ``ax``; returns the image."""
    M, N = (int(v) for v in arrays["shape"])
    x, y = arrays["axis_0"], arrays["axis_1"]
    megno = np.ma.masked_invalid(arrays["megno"].reshape(M, N))
    cmap = matplotlib.colormaps["magma"].with_extremes(bad="#dddddd")
    image = ax.pcolormesh(_edges(x), _edges(y), megno, cmap=cmap, vmin=0.0, vmax=MEGNO_CAP,
                          shading="flat", rasterized=True)
    ax.contour(arrays["boundary_0"], arrays["boundary_1"], arrays["boundary_H"],
               levels=[float(arrays["energy"])], colors="#1f77b4", linewidths=1.0)
    status = arrays["status"]
    failed = (status != "success") & (status != "not_run")
    if failed.any():
        i = np.flatnonzero(failed)
        ax.plot(x[i % N], y[i // N], **figures.FAILED, label=f"{i.size} cells failed")
        ax.legend(loc="upper right")
    ax.set_xlim(x[0] - (x[1] - x[0]) / 2, x[-1] + (x[-1] - x[-2]) / 2)
    ax.set_ylim(y[0] - (y[1] - y[0]) / 2, y[-1] + (y[-1] - y[-2]) / 2)
    ax.set_aspect("equal")
    return image


def _edges(centres: np.ndarray) -> np.ndarray:
    middle = (centres[1:] + centres[:-1]) / 2
    return np.concatenate([[2 * centres[0] - middle[0]], middle,
                           [2 * centres[-1] - middle[-1]]])


def _tex(section: str) -> str:
    name, _, value = section.partition("=")
    return f"{name[0]}_{{{name[1:]}}} = {value}"
