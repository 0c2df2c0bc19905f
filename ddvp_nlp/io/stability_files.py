"""Writing the stability of periodic orbits: ``stability.json`` beside an orbit's run folder
files, a family's ``stability.csv``, and a followed family (``follow_periodic_family``):
``family.csv`` with every member's multipliers, ``bifurcations.csv`` and ``.json``, a folder per
bifurcation orbit and ``family.png`` (period and stability indices against the energy, each
orbit coloured by its verdict, the bifurcations marked). Every set is written through
``atomic.py`` (scratch files renamed into place under the folder's lock): a crash leaves the
old set or the new one."""

from __future__ import annotations

import csv
import io
import json

import numpy as np

from . import atomic
from .run_folder import json_default

STABILITY_COLUMNS = ("energy", "status", "period", "verdict", "indices", "moduli",
                     "trivial_error", "exact_verdict", "exact_indices", "index_error",
                     "exact_closure", "exact_distance", "period_derivative")


def _write_set(out, files: dict, meta: dict | None = None) -> None:
    """``files`` (name -> writer) into the folder ``out`` (a path or an open
    `OutputFolder`): with ``meta``, one set under the manifest
    ``meta.json``; without, each file replaced on its own beside a set another writer made
    (an orbit's run folder), scratch file first, renamed into place."""
    with atomic.output_folder(out) as folder:
        if meta is None:
            for name, write in files.items():
                folder.replace(name, write)
        else:
            folder.commit(files, meta)


def _json(value):
    return atomic.text(json.dumps(value, indent=2, default=json_default) + "\n")


def _csv(rows: list[dict], columns):
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return atomic.text(buffer.getvalue())


def _numbers(values) -> str:
    """Complex numbers as ``a`` or ``a+bj``, joined by ``;`` (one CSV cell)."""
    return ";".join(f"{v.real:.12g}" if v.imag == 0 else f"{v.real:.12g}{v.imag:+.6g}j"
                    for v in np.asarray(values, complex))


def stability_row(energy: float, orbit, stability) -> dict:
    """One orbit's row of ``stability.csv`` / a followed ``family.csv``."""
    row = {"energy": energy, "status": orbit.status.code,
           "period": orbit.orbit.period if orbit.orbit is not None else None}
    if stability is None:
        return row
    exact, closed = stability.exact, stability.exact_orbit
    row.update(verdict=stability.verdict, indices=_numbers(stability.indices),
               moduli=";".join(f"{abs(v):.12g}" for v in stability.multipliers),
               trivial_error=stability.trivial_error,
               exact_verdict=None if exact is None else exact.verdict,
               exact_indices=None if exact is None else _numbers(exact.indices),
               index_error=stability.index_error,
               exact_closure=None if closed is None else closed.closure,
               exact_distance=None if closed is None else closed.distance,
               period_derivative=stability.extra.get("period_derivative"))
    return row


def write_stability(out, stability) -> dict:
    """``stability.json`` in the run folder ``out``; returns what it holds."""
    data = stability.as_dict()
    _write_set(out, {"stability.json": _json(data)})
    return data


def write_family_stability(out, family: list, stabilities: list) -> list[dict]:
    """``stability.csv`` of a natural-parameter family (``[(E, Solution)]`` with one
    `Stability` or ``None`` each), and ``stability.json`` in each ``E=`` folder."""
    rows = [stability_row(energy, orbit, stability)
            for (energy, orbit), stability in zip(family, stabilities, strict=True)]
    with atomic.output_folder(out) as folder:
        _write_set(folder, {"stability.csv": _csv(rows, STABILITY_COLUMNS)})
        for (energy, _), stability in zip(family, stabilities, strict=True):
            if stability is not None:
                with folder.subfolder(f"E={energy:.6g}") as member:
                    write_stability(member, stability)
    return rows


def write_followed_family(out, scene, family, params: dict, plot: bool = True,
                          write_orbit=None) -> list[dict]:
    """The files of a followed family (module docstring); ``write_orbit(folder, scene,
    solution, params)`` writes a bifurcation orbit's run folder (``periodic_runs``)."""
    rows = [{**stability_row(m.energy, m.orbit, m.stability), "arclength": m.arclength,
             "slope": m.slope} for m in family.members]
    found = [{"number": j + 1, **b.as_dict()} for j, b in enumerate(family.bifurcations)]
    columns = (*STABILITY_COLUMNS, "arclength", "slope")
    summary = {"scene": scene.name, "params": params, "orbits": len(rows),
               "complete": family.complete, "message": family.message,
               "seconds": family.seconds, "bifurcations": found}
    writers = {"family.csv": _csv(rows, columns), "bifurcations.json": _json(summary),
               "bifurcations.csv": _csv([{k: v for k, v in b.items() if not isinstance(
                   v, (list, dict))} for b in found], _bifurcation_columns(found))}
    with atomic.output_folder(out) as folder:
        for j, bifurcation in enumerate(family.bifurcations):
            with folder.subfolder(f"bifurcation-{j + 1}") as orbit_folder:
                if write_orbit is not None:
                    write_orbit(orbit_folder, scene, bifurcation.orbit, params)
                write_stability(orbit_folder, bifurcation.stability)
        if plot and rows:
            from .orbit_figures import plot_followed_family

            writers["family.png"] = lambda handle: plot_followed_family(
                family, f"{scene.name}: periodic family", handle)
        _write_set(folder, writers, meta=summary)
    return rows


def _bifurcation_columns(found: list[dict]) -> list[str]:
    columns = ["number", "kind", "energy", "after_member", "period", "status"]
    for row in found:
        columns += [k for k, v in row.items() if k not in columns
                    and not isinstance(v, (list, dict))]
    return columns
