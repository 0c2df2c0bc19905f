"""Which method is cheapest for an error and a horizon: `HorizonComparison`, what
``compare(..., horizons=[...])`` returns, its `best` and its crossover horizons.

**The rule.** At a measured horizon ``T``, a method's cost to reach error ``E`` is read off its
Pareto front (its successful runs that no cheaper run beats, cost against error): between two
runs that bracket ``E`` it is interpolated linearly in ``log cost`` against ``log error``
(`time_to_reach`); where the method's cheapest run is already below ``E`` the cost is that
run's, an upper bound (a coarser run, not made, could be cheaper); a method none of whose runs
reaches ``E`` has no cost. Between two measured horizons ``T_a < T < T_b``, the cost of a
method that reaches ``E`` at both is interpolated linearly in ``log cost`` against ``log T``
(an upper bound if either end is one); a method that reaches ``E`` at only one of them has no
cost there. Outside the measured horizons nothing is claimed. The cheapest is the least cost;
it is ``certain`` unless another method's cost is only an upper bound (that method could be
cheaper). ``cost`` is the column read: ``run_s`` (wall, best of the repeats), ``cpu_s`` (the
CPU of that call) or ``steps`` (no clock: the same on every machine, blind to the work per
step).

**Crossovers.** For an error ``E``, the cheapest method is followed along ``log T`` between the
shortest and the longest horizon (the rule above, on `CROSSOVER_GRID` points per pair of
measured horizons, each change of winner then bisected to `CROSSOVER_RTOL` in ``T``): a
`Crossover` is the horizon from which another method is cheapest. Where the change comes from
a method that reaches ``E`` at one measured horizon only (its cost exists there and not
between), the crossover is that measured horizon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from ..errors import InputError
from ..validation import check_real
from .work_precision import ERROR_KINDS, FINEST_LEVEL, methods_in, time_to_reach

COSTS = ("run_s", "cpu_s", "steps")
CROSSOVER_GRID = 64
CROSSOVER_RTOL = 1e-3


@dataclass(frozen=True)
class Choice:
    """The answer of `HorizonComparison.best`: ``method`` (``None`` when no method reaches the
    error at the horizon; ``why`` says why), its ``seconds`` (the cost read, in its units),
    ``upper_bound`` (its cost is its cheapest run's), ``certain`` (no other method's cost is
    only a bound), ``ranking`` (every method that reaches the error: ``(method, cost,
    upper_bound)``, cheapest first) and ``why``, the rule's verdict in words. True when a
    method was found."""

    error: float
    horizon: float
    kind: str
    cost: str
    method: str | None
    seconds: float
    upper_bound: bool
    certain: bool
    ranking: tuple
    why: str

    def __bool__(self) -> bool:
        return self.method is not None


@dataclass(frozen=True)
class Crossover:
    """From ``horizon`` on, ``after`` is cheaper than ``before`` to reach ``error`` (of
    ``kind``), by the interpolation rule; ``between``: the measured horizons around it."""

    error: float
    kind: str
    before: str | None
    after: str | None
    horizon: float
    between: tuple[float, float]

    def where(self) -> str:
        """``T = 446``, or ``just above T = 10`` where ``before`` reaches the error at the
        measured horizon ``10`` and not at the next (it has no cost between)."""
        low = self.between[0]
        if self.horizon <= low * (1 + 2 * CROSSOVER_RTOL):
            return f"just above T = {low:g}"
        return f"T = {self.horizon:.3g}"


@dataclass
class HorizonComparison:
    """The comparison at each horizon: ``results`` (horizon to `WorkPrecision`, shortest
    first, ``t_end = t0 + horizon * unit``), ``notes`` (per horizon, the runs each sweep left
    out and why)."""

    results: dict
    unit: float = 1.0
    notes: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        horizons = ", ".join(f"{h:g}" for h in self.results)
        runs = sum(len(r.rows) for r in self.results.values())
        return f"HorizonComparison(horizons {horizons}: {runs} runs)"

    @property
    def horizons(self) -> list[float]:
        return list(self.results)

    @property
    def rows(self) -> list[dict]:
        """Every run, each with its ``horizon``."""
        return [{"horizon": h, **row} for h, result in self.results.items()
                for row in result.rows]

    def best(self, error: float, horizon: float, kind: str = "trajectory_error",
             cost: str = "run_s") -> Choice:
        """The method cheapest to reach ``error`` (of ``kind``) at ``horizon``, by the rule of
        the module docstring; a `Choice` whose ``method`` is ``None`` (and ``why`` says why)
        when no method reaches it there."""
        error, kind, cost = _checked(error, kind, cost)
        horizon = check_real("horizon", horizon, positive=True)
        costs, why = costs_at(self.fronts(kind, cost), error, horizon)
        choice = choose(costs, error, horizon, kind, cost, why)
        if choice and cost == "run_s":  # the CPU time beside the wall time, by the same rule
            cpu, _ = costs_at(self.fronts(kind, "cpu_s"), error, horizon)
            if choice.method in cpu:
                choice = replace(choice, why=choice.why.replace(
                    " s (", f" s wall, {cpu[choice.method][0]:.3g} s CPU (", 1))
        return choice

    def fronts(self, kind: str = "trajectory_error", cost: str = "run_s") -> dict:
        """``{horizon: {method: Pareto front [(cost, error), ...]}}``."""
        _checked(1e-3, kind, cost)
        return {h: {m: front(result.rows, m, kind, cost) for m in methods_in(result.rows)}
                for h, result in self.results.items()}

    def levels(self, kind: str = "trajectory_error") -> list[float]:
        """The decades of error (1e-1 down to `FINEST_LEVEL`) some method reaches at two
        horizons or more: where a crossover can be looked for."""
        fronts = self.fronts(kind)
        found = []
        for k in range(1, round(-math.log10(FINEST_LEVEL)) + 1):
            level = 10.0 ** -k
            reached = sum(any(time_to_reach(f, level) for f in by_method.values())
                          for by_method in fronts.values())
            if reached >= min(2, len(fronts)):
                found.append(level)
        return found

    def crossovers(self, errors=None, kind: str = "trajectory_error",
                   cost: str = "run_s") -> list[Crossover]:
        """Every horizon where the cheapest method to reach each error changes (module
        docstring); ``errors`` default: `levels`."""
        found = []
        fronts = self.fronts(kind, cost)
        for error in (self.levels(kind) if errors is None else errors):
            error, kind, cost = _checked(error, kind, cost)
            found += crossings(fronts, error, kind)
        return found

    def winners(self, error: float, kind: str = "trajectory_error", cost: str = "run_s",
                points: int = CROSSOVER_GRID) -> list[tuple[float, str | None]]:
        """``(horizon, cheapest method or None)`` on ``points`` horizons per interval between
        measured horizons, evenly in ``log T`` (what the crossover figure draws)."""
        error, kind, cost = _checked(error, kind, cost)
        fronts = self.fronts(kind, cost)
        return [(h, winner_at(fronts, error, h)) for h in grid(list(fronts), points)]

    def crossover_words(self, errors=None, kind: str | None = None,
                        cost: str = "run_s") -> list[str]:
        """The crossovers in words: per error kind, one line per run of error levels with the
        same cheapest methods along the horizons."""
        lines = []
        for each in ([kind] if kind else list(ERROR_KINDS)):
            fronts = self.fronts(each, cost)
            said = [(error, in_words(fronts, error, each, self.unit))
                    for error in (self.levels(each) if errors is None else errors)]
            groups = []
            for error, text in said:
                if groups and groups[-1][2] == text:
                    groups[-1][1] = error
                else:
                    groups.append([error, error, text])
            name = ERROR_KINDS[each].split(" max")[0]
            lines += [f"- {name} <= {hi:.0e}: {text}" if hi == lo else
                      f"- {name} <= {hi:.0e} down to <= {lo:.0e}: {text}"
                      for hi, lo, text in groups]
        return lines or ["- No error level is reached at two horizons: no crossover to look "
                         "for."]

    def plot(self, path=None, *, title: str | None = None):
        """Work-precision at each horizon (a column per horizon); with ``path`` (PNG, SVG or
        PDF by its suffix) also written there. Returns the figure."""
        from ..io.horizons_figure import plot_horizons

        rows = {h: result.rows for h, result in self.results.items()}
        return _drawn(lambda target: plot_horizons(
            rows, target, title=title or "error against run time", unit=self.unit,
            time_dependent=_time_dependent(self)), path)

    def plot_crossover(self, path=None, *, errors=None, cost: str = "run_s",
                       title: str | None = None):
        """The crossover figure (`io.crossover_figure`): for each error level (``errors``,
        default `levels` of each kind), the cheapest method along the horizons. Returns the
        figure; with ``path`` (PNG, SVG or PDF) also written there."""
        from ..io.crossover_figure import plot_crossover

        maps = {kind: [(e, self.winners(e, kind, cost))
                       for e in (self.levels(kind) if errors is None else errors)]
                for kind in ERROR_KINDS}
        methods = list(dict.fromkeys(m for r in self.results.values()
                                     for m in methods_in(r.rows)))
        return _drawn(lambda target: plot_crossover(
            maps, methods, self.horizons, target, title=title or "cheapest method",
            unit=self.unit, cost=cost, time_dependent=_time_dependent(self)), path)

    @classmethod
    def read_csv(cls, path, unit: float = 1.0) -> HorizonComparison:
        """The comparison `to_csv` wrote, for its rankings, crossovers and figures (its
        ``results`` hold the rows only: no scene, no reference)."""
        import csv
        from types import SimpleNamespace

        from .work_precision import ADDED, ROWS

        found: dict[float, list[dict]] = {}
        with open(path, newline="") as handle:
            for row in csv.DictReader(handle):
                horizon = float(row.pop("horizon"))
                found.setdefault(horizon, []).append(ROWS.parse({**ADDED, **row}))
        return cls({h: SimpleNamespace(rows=rows) for h, rows in sorted(found.items())}, unit)

    def to_csv(self, path) -> None:
        """Every run with its ``horizon``, as ``work_precision.csv`` with a first column."""
        import csv

        from .work_precision import COLUMNS

        columns = ["horizon", *(c for c in COLUMNS if c not in ("fingerprint", "row_sha256"))]
        with open(path, "w", newline="") as handle:
            writer = csv.DictWriter(handle, columns, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(self.rows)


def _time_dependent(study) -> bool:
    first = next(iter(study.results.values()), None)
    scene = getattr(first, "scene", None)
    return bool(scene is not None and scene.system.time_dependent)


def _drawn(draw, path):
    from ..io.figures import Keep, format_of, save, styled

    keep = Keep()
    draw(keep)
    if path is not None:
        with styled():
            save(keep.figure, path, format_of(path))
    return keep.figure


def _checked(error, kind, cost):
    if kind not in ERROR_KINDS:
        raise InputError(f"kind must be one of {', '.join(ERROR_KINDS)}, got {kind!r}")
    if cost not in COSTS:
        raise InputError(f"cost must be one of {', '.join(COSTS)}, got {cost!r}")
    return check_real("error", error, positive=True), kind, cost


def front(rows, method, kind, cost) -> list[tuple[float, float]]:
    """``(cost, error)`` of the successful runs of ``method`` that no cheaper run beats."""
    points = sorted((float(r[cost]), r[kind]) for r in rows
                    if r["method"] == method and r["status"] == "success"
                    and math.isfinite(r[kind]) and r[kind] > 0
                    and math.isfinite(float(r[cost])) and float(r[cost]) > 0)
    found = []
    for value, error in points:
        if not found or error < found[-1][1]:
            found.append((value, error))
    return found


def costs_at(fronts: dict, error: float, horizon: float) -> tuple[dict, str]:
    """``{method: (cost, upper_bound)}`` at ``horizon`` by the rule, and how it was read."""
    measured = sorted(fronts)
    horizon = next((h for h in measured if abs(h - horizon) <= 1e-12 * h), horizon)
    if horizon in fronts:
        return ({m: hit for m, f in fronts[horizon].items()
                 if (hit := time_to_reach(f, error)) is not None},
                f"measured at T = {horizon:g}")
    if not measured or not measured[0] < horizon < measured[-1]:
        return {}, (f"T = {horizon:g} is outside the measured horizons "
                    f"{', '.join(f'{h:g}' for h in measured)}: nothing is claimed there")
    upper = next(h for h in measured if h > horizon)
    lower = max(h for h in measured if h < horizon)
    fraction = math.log(horizon / lower) / math.log(upper / lower)
    found = {}
    for method in fronts[lower]:
        a = time_to_reach(fronts[lower][method], error)
        b = time_to_reach(fronts[upper].get(method, []), error)
        if a is not None and b is not None:
            found[method] = (math.exp(math.log(a[0]) + fraction * math.log(b[0] / a[0])),
                             a[1] or b[1])
    return found, f"interpolated in log T between T = {lower:g} and T = {upper:g}"


def choose(costs: dict, error, horizon, kind, cost, how: str) -> Choice:
    """The `Choice` of the least cost, or of none with why."""
    ranking = tuple(sorted(((m, c, bound) for m, (c, bound) in costs.items()),
                           key=lambda item: item[1]))
    name = ERROR_KINDS[kind].split(" max")[0]
    if not ranking:
        why = (how if "outside" in how else
               f"no method reaches {name} {error:.3g} at T = {horizon:g} ({how})")
        return Choice(error, horizon, kind, cost, None, math.nan, False, False, (), why)
    method, value, bound = ranking[0]
    doubtful = [m for m, _, other_bound in ranking[1:] if other_bound]
    why = (f"`{method}` is cheapest to reach {name} {error:.3g} at T = {horizon:g}: "
           f"{'at most ' if bound else ''}{value:.3g} {'steps' if cost == 'steps' else 's'} "
           f"({how})")
    if doubtful:
        why += (f"; not certain: the costs of {', '.join(f'`{m}`' for m in doubtful)} are "
                "upper bounds (their coarsest runs already reach it)")
    return Choice(error, horizon, kind, cost, method, value, bound, not doubtful, ranking, why)


def winner_at(fronts, error, horizon) -> str | None:
    costs, _ = costs_at(fronts, error, horizon)
    return min(costs, key=lambda m: costs[m][0]) if costs else None


def grid(horizons: list[float], points: int) -> list[float]:
    """``points`` horizons per interval between measured ones, evenly in ``log T``, the
    measured ones among them."""
    horizons = sorted(horizons)
    found = [horizons[0]] if horizons else []
    for a, b in zip(horizons, horizons[1:], strict=False):
        found += [a * (b / a) ** (i / points) for i in range(1, points)] + [b]
    return found


def crossings(fronts, error, kind) -> list[Crossover]:
    """Each horizon where the cheapest method to reach ``error`` changes (module
    docstring)."""
    measured = sorted(fronts)
    found = []
    for a, b in zip(measured, measured[1:], strict=False):
        points = grid([a, b], CROSSOVER_GRID)
        winners = [winner_at(fronts, error, h) for h in points]
        for i in range(len(points) - 1):
            lo, hi = points[i], points[i + 1]
            if winners[i] == winners[i + 1]:
                continue
            while hi / lo > 1 + CROSSOVER_RTOL:
                middle = math.sqrt(lo * hi)
                if winner_at(fronts, error, middle) == winners[i]:
                    lo = middle
                else:
                    hi = middle
            found.append(Crossover(error, kind, winners[i], winners[i + 1], hi, (a, b)))
    return found


def in_words(fronts, error, kind, unit: float = 1.0) -> str:
    """Which method is cheapest from which horizon, in one sentence."""
    measured = sorted(fronts)
    first = winner_at(fronts, error, measured[0]) if measured else None
    changes = crossings(fronts, error, kind)
    if first is None and not changes:
        return "no method reaches it at any measured horizon."
    units = f" x {unit:.4g}" if unit != 1 else ""
    text = (f"`{first}` from T = {measured[0]:g}" if first else
            f"none reaches it at T = {measured[0]:g}")
    for change in changes:
        who = f"`{change.after}`" if change.after else "none reaches it"
        text += f"; {who} from {change.where()}"
    return text + f" (up to T = {measured[-1]:g}{units})."
