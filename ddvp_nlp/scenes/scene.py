"""Scenes: a system plus the data to run it, declared in a small Python file.

A scene file defines ``scene = Scene(...)`` with only what it needs::

    import casadi as ca
    from ddvp_nlp import Scene

    def hamiltonian(q, p, t, w):
        return (p[0]**2 + w**2 * q[0]**2) / 2

    scene = Scene(hamiltonian, n=1, params={"w": 1.0}, q0=[1.0], p0=[0.0], tau0=0.1, t_end=10)

The built-in scenes are the files of the top-level ``problems/`` folder (installed as
``ddvp_nlp.problems``); any other path to a ``.py`` file works the same way.
"""

from __future__ import annotations

import dataclasses
import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..errors import InputError
from ..physics import HamiltonianSystem, HigherOrderSystem, Lagrangian, LagrangianSystem
from ..validation import (
    check_degrees,
    check_integer,
    check_parameter_ranges,
    check_parameter_values,
    check_real,
    check_step,
)
from .run_config import (
    BOUNDARY_NODES,
    RUN_SETTINGS,
    BoundaryConfig,
    Endpoints,
    HigherRunConfig,
    RunConfig,
    resolve_boundary,
    resolve_run,
    split_parameters,
)


@dataclass(frozen=True)
class PeriodicSettings:
    """A scene's defaults for ``ddvp periodic`` (``solvers/periodic``).

    Attributes:
        section: the phase condition on node 0, ``"NAME=VALUE"``.
        energy: the default prescribed energy.
        nodes: the default number of nodes of the closed grid (intervals + 1).
        start: ``(q, p)``, the direction along which the section's point at ``energy`` is
            looked for.
        integrals: first integrals besides ``H`` whose flows are symmetries.
        angles: angle coordinates (``("q1",)``), which may close with whole turns.
        families: further families by name, each its own ``PeriodicSettings`` (section and
            start; read by ``scripts/pages/periodic_page.py``).
        guess: optional ``guess(energy, **params) -> {"t", "q", "p"}``, one period of a start
            near the orbit at ``energy``, used when no guess is given (where no ray from the
            origin through the orbit makes the section's point, as about a Lagrange point).
        period: optional ``period(energy, **params)``, the exact period ``T(E)`` of this
            family's orbits where it is known in closed form (NaN at energies the family does
            not reach), elementwise over an array of energies: drawn under the discrete
            periods in a family's figure, with their relative difference.
    """

    section: str = "p1=0"
    energy: float | None = None
    nodes: int = 201
    start: tuple | None = None
    integrals: tuple = ()
    angles: tuple = ()
    families: Mapping[str, PeriodicSettings] = field(default_factory=dict)
    guess: Callable[..., Mapping] | None = None
    period: Callable[..., object] | None = None

    def __post_init__(self):
        if not isinstance(self.section, str) or "=" not in self.section:
            raise InputError(f"PeriodicSettings section must be 'NAME=VALUE' such as 'p1=0', "
                             f"got {self.section!r}")
        check_real("PeriodicSettings energy", self.energy, allow_none=True)
        object.__setattr__(self, "nodes", check_integer("PeriodicSettings nodes", self.nodes,
                                                        minimum=3))
        if self.start is not None and (isinstance(self.start, (str, Mapping))
                                       or len(self.start) != 2):
            raise InputError(f"PeriodicSettings start must be a pair (q, p), got "
                             f"{self.start!r}")
        for name in ("integrals", "angles"):
            value = getattr(self, name)
            if isinstance(value, str) or not isinstance(value, (tuple, list)):
                raise InputError(f"PeriodicSettings {name} must be a tuple such as ('q1',), "
                                 f"got {value!r}")
            object.__setattr__(self, name, tuple(value))
        if not isinstance(self.families, Mapping):
            raise InputError(f"PeriodicSettings families must be a dict of names to settings, "
                             f"got {self.families!r}")
        object.__setattr__(self, "families", {
            name: as_settings(f"PeriodicSettings families[{name!r}]", value, PeriodicSettings)
            for name, value in self.families.items()})
        for name in ("guess", "period"):
            value = getattr(self, name)
            if value is not None and not callable(value):
                raise InputError(f"PeriodicSettings {name} must be a function or None, got "
                                 f"{value!r}")

    def exact_period(self, section: str, params: Mapping) -> Callable | None:
        """``T(E)`` (one argument, ``params`` bound) of the family through ``section``: this
        family's or one of `families`' ``period`` whose section is ``section`` (spaces
        ignored), else ``None`` (no closed form declared for that family)."""
        wanted = section.replace(" ", "")
        for settings in (self, *self.families.values()):
            if settings.period is not None and settings.section.replace(" ", "") == wanted:
                period = settings.period
                return lambda energy: np.asarray(period(np.asarray(energy, float), **params),
                                                 dtype=float)
        return None


def as_settings(where: str, value, kind):
    """A scene's ``boundary``/``periodic`` setting as its object: ``None``, a ``kind``, a
    mapping of its field names (``{"energy": 0.5}``, as the docs write it) or, for
    `Endpoints`, a tuple of its fields in order (``(q_start, q_end, t_span, nodes)``); each
    made by the class, so both forms pass the same checks. Anything else, or an unknown field,
    is an `InputError` naming ``where``."""
    if value is None or isinstance(value, kind):
        return value
    fields = [f.name for f in dataclasses.fields(kind)]
    shapes = "a dict of its fields" + (" or a tuple (q_start, q_end, t_span, nodes)"
                                       if kind is Endpoints else "")
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in fields]
        if unknown:
            raise InputError(f"{where}: unknown field {unknown[0]!r} of {kind.__name__} "
                             f"(known: {', '.join(fields)})")
        arguments, positional = dict(value), ()
    elif kind is Endpoints and isinstance(value, (tuple, list)) and len(value) <= len(fields):
        arguments, positional = {}, tuple(value)
    else:
        raise InputError(f"{where} must be {kind.__name__}(...), {shapes}, or None, got "
                         f"{value!r}")
    try:
        return kind(*positional, **arguments)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


# `Scene.system` by what it is built from, held while a scene (or anything else) holds it.
_SYSTEMS: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


@dataclass(eq=False)
class Scene:
    """A mechanical system with its defaults.

    Attributes:
        hamiltonian: ``H(q, p, t, **params)`` on CasADi symbols, or ``Lagrangian(L)`` with
            ``L(q, v, t, **params)`` (``ddvp_nlp.lagrangian``).
        n: degrees of freedom.
        q0, p0: initial state, or a function of the parameters returning it.
        v0: for a Lagrangian scene, the first interval's velocity instead of ``p0`` (the march
            takes ``q_1 = q_0 + tau0 v0`` and ``p_0`` by the discrete Legendre transform).
        tau0: default first step.
        t_end: default end time.
        t0: default start time.
        params: parameter names and defaults.
        exact: optional exact solution ``exact(t, q0, p0, t0, **params) -> (q, p)`` with ``t`` of
            shape ``(N,)`` and ``q``, ``p`` of shape ``(N, n)``; it raises ``ValueError`` for a
            start it does not cover (an unbound Kepler orbit, a rotating pendulum), and the
            studies then use a DOP853 reference, the run files no exact error.
        invariants: optional named first integrals besides ``H``, ``f(q, p, **params) -> (N,)``.
        boundary: optional default fixed-endpoint data, an `Endpoints` (or the same as a
            dict of its fields, or a tuple ``(q_start, q_end, t_span, nodes)``).
        name, description: set from the file name and docstring when loaded.
        source: the name or path it was loaded from (empty for a scene made in Python); grid
            tasks reload the scene from it in their own process.
        digest: the SHA-256 of the file it was loaded from (empty for a scene made in
            Python): what a run folder's name and a resumed run's check are made of.
        periodic: optional defaults of ``ddvp periodic``, a `PeriodicSettings` (or a dict of
            its fields: ``periodic={"energy": 0.5, "angles": ("q1",)}``).
        scheme: optional scheme ``ddvp march`` and ``ddvp bvp`` use when ``--scheme`` is not
            given (default ``None``: the paper's ``vddvp``); ``ddvp scenes`` shows it.
        ranges: optional intervals of the parameters where the scene means something, e.g.
            ``{"e": "[0, 1)"}`` for an eccentricity; a value outside is refused by name before
            anything is built.
        constraints: optional holonomic constraints ``g(q, t, **params)`` returning a CasADi
            vector (``physics/constraints.py``): the scene's system carries them, and the march
            keeps ``g = 0`` and its hidden constraint at every node (docs/constraints.md).
    """

    hamiltonian: Callable[..., object]
    n: int
    q0: object = None
    p0: object = None
    tau0: float | None = None
    t_end: float | None = None
    t0: float = 0.0
    params: Mapping[str, float] = field(default_factory=dict)
    exact: Callable[..., tuple] | None = None
    invariants: Mapping[str, Callable[..., np.ndarray]] = field(default_factory=dict)
    boundary: Endpoints | None = None
    name: str = "scene"
    source: str = ""
    description: str = ""
    digest: str = ""
    v0: object = None
    periodic: PeriodicSettings | None = None
    scheme: str | None = None
    ranges: Mapping[str, str] = field(default_factory=dict)
    constraints: Callable[..., object] | None = None

    def __post_init__(self):
        _check_common(self)
        self.periodic = as_settings(f"scene {self.name!r}: periodic", self.periodic,
                                    PeriodicSettings)
        for key in ("q0", "tau0", "t_end"):
            if getattr(self, key) is None:
                raise InputError(f"scene needs {key}")
        if (self.p0 is None) == (self.v0 is None):
            raise InputError("scene needs exactly one of p0 and v0")
        if self.v0 is not None and not isinstance(self.hamiltonian, Lagrangian):
            raise InputError("v0 is for a scene declared by Lagrangian(L); give p0")

    @cached_property
    def system(self) -> HamiltonianSystem:
        """The scene's system; its angles are those of ``periodic`` (the check's too). Scenes
        made of the same function objects with the same ``n``, parameters, name, angles and
        constraints share one system (a scene loaded again, ``loader.py``), and with it what
        was built for it."""
        angles = self.periodic.angles if self.periodic is not None else ()
        key = (self.hamiltonian, self.n, tuple(self.params.items()), self.name, tuple(angles),
               self.constraints)
        try:
            shared = _SYSTEMS.get(key)
        except TypeError:  # a parameter or function that cannot be hashed: not shared
            return self._built(angles)
        if shared is None:
            shared = self._built(angles)
            _SYSTEMS[key] = shared
        return shared

    def _built(self, angles) -> HamiltonianSystem:
        if isinstance(self.hamiltonian, Lagrangian):
            return LagrangianSystem(self.hamiltonian.function, self.n, dict(self.params),
                                    name=self.name, angles=angles,
                                    constraints=self.constraints)
        return HamiltonianSystem(self.hamiltonian, self.n, dict(self.params), name=self.name,
                                 angles=angles, constraints=self.constraints)

    def resolve_boundary(self, overrides: Mapping[str, object] | None = None,
                         nodes: int | None = None) -> BoundaryConfig:
        """Fixed-endpoint data: the scene's ``boundary`` with ``overrides`` (parameters,
        ``q_start``, ``q_end``, ``t0``, ``t_end``) and ``nodes`` applied."""
        return resolve_boundary(self, overrides, nodes)

    def resolve(self, overrides: Mapping[str, object] | None = None) -> RunConfig:
        """Defaults with ``overrides`` applied: parameters, ``t0``, ``tau0``, ``t_end``, ``q0``,
        ``p0``. Unknown names are an error that lists the known ones."""
        return resolve_run(self, overrides)

    def exact_states(self, config: RunConfig) -> Callable | None:
        """The scene's exact solution through the run's start as ``exact(t) -> z`` (rows), for
        the accuracy check, or ``None`` (no exact solution, a start it does not cover, a start
        from ``v0`` whose ``p0`` the march computes)."""
        if self.exact is None or config.p0 is None:
            return None
        q0, p0, t0, params = config.q0, config.p0, config.t0, config.params
        try:
            probe = self.exact(np.array([t0, t0]), q0, p0, t0, **params)
        except ValueError:
            return None
        except Exception as exc:  # the scene's own code: say whose it is
            raise InputError(f"scene {self.name!r}: exact(t, q0, p0, t0, **params) failed: "
                             f"{type(exc).__name__}: {exc}") from None
        self._check_exact(probe, 2)

        def exact(t):
            t = np.asarray(t, float)
            found = self.exact(t, q0, p0, t0, **params)
            q, p = self._check_exact(found, t.size)
            return np.hstack([q, p])
        return exact

    def _check_exact(self, found, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``exact``'s answer at ``count`` times as ``(q, p)`` rows ``(count, n)`` each, or an
        `InputError` naming the scene and the shape it gave (it was an internal error)."""
        n = self.n
        try:
            if not isinstance(found, (tuple, list)) or len(found) != 2:
                raise TypeError("not a pair")
            q, p = found
            q = np.asarray(q, float).reshape(count, n)
            p = np.asarray(p, float).reshape(count, n)
        except (TypeError, ValueError):
            shapes = (tuple(np.shape(part)) for part in found) if isinstance(found, tuple) \
                else (np.shape(found),)
            raise InputError(
                f"scene {self.name!r}: exact(t, ...) must return (q, p), each of shape "
                f"(len(t), {n}) = ({count}, {n}); it returned shapes "
                f"{', '.join(map(str, shapes))}") from None
        return q, p

    def march(self, t_end: float | None = None, *, overrides: Mapping[str, object] | None = None,
              **options):
        """``march`` from this scene's defaults (``resolve(overrides)``: parameters, start,
        ``t0``, ``tau0``, ``t_end``; ``t_end`` here wins), its default scheme, and ``options``
        passed on (``steps=``, ``accuracy=``, ``compilation=``, ``output=``, ``scheme=``...)."""
        from ..solvers import march  # loaded when called

        config = self.resolve(overrides)
        options.setdefault("scheme", self.scheme or "vddvp")
        options.setdefault("tau0", config.tau0)
        return march(self.system, config.q0, config.p0, (config.t0, t_end or config.t_end),
                     v0=config.v0, params=config.params, **options)

    def solve_bvp(self, *, overrides: Mapping[str, object] | None = None,
                  nodes: int | None = None, **options):
        """``solve_bvp`` on this scene's fixed-endpoint data (``resolve_boundary``) and default
        scheme, ``options`` passed on."""
        from ..solvers import solve_bvp  # loaded when called

        data = self.resolve_boundary(overrides, nodes)
        options.setdefault("scheme", self.scheme or "vddvp")
        return solve_bvp(self.system, data.q_start, data.q_end, data.t_span, nodes=data.nodes,
                         params=data.params, **options)

    def solve_periodic(self, energy: float | None = None, *, nodes: int | None = None,
                       overrides: Mapping[str, object] | None = None, **options):
        """``solve_periodic`` with this scene's periodic defaults (``PeriodicSettings``:
        energy, nodes, section, start, integrals, angles, the guess function) and its default
        scheme, ``options`` passed on. (Named so because ``periodic`` is the settings field.)"""
        from ..solvers import solve_periodic  # loaded when called

        settings = self.periodic or PeriodicSettings()
        energy = settings.energy if energy is None else energy
        if energy is None:
            raise InputError(f"scene {self.name!r} declares no periodic energy: give energy=")
        params, _ = split_parameters(self, overrides, ())
        if settings.guess is not None:
            options.setdefault("guess", settings.guess(energy, **params))
        for name in ("section", "start", "integrals", "angles"):
            if getattr(settings, name) is not None:
                options.setdefault(name, getattr(settings, name))
        options.setdefault("scheme", self.scheme or "vddvp")
        return solve_periodic(self.system, energy=energy, nodes=nodes or settings.nodes,
                              params=params, **options)


@dataclass(eq=False)
class HigherOrderScene:
    """A scene declared by ``L(q, v, t, **params)`` with ``v[m-1]`` the ``m``-th difference.

    Attributes:
        lagrangian, n, order, params: the system.
        exact: ``exact(t, **params) -> q`` of shape ``(N, n)``: the motion the scene follows. The
            march starts from ``2 * order`` of its nodes spaced ``tau0`` from ``t0``; the
            fixed-endpoint problem takes ``order`` of its nodes at each end of ``t_span`` on the
            uniform grid of ``nodes`` nodes.
        tau0, t_end, t0: march defaults; ``boundary``: an `Endpoints` with ``t_span``
            and ``nodes`` (the end positions come from ``exact``).
        scheme: optional scheme ``ddvp march`` and ``ddvp bvp`` use when ``--scheme`` is not
            given (the energy rules have no positive step on some of these; ``fixed`` always
            has one).
        name, source, description, digest: as for `Scene`.
    """

    lagrangian: Callable[..., object]
    n: int
    order: int
    exact: Callable[..., np.ndarray]
    tau0: float
    t_end: float
    t0: float = 0.0
    params: Mapping[str, float] = field(default_factory=dict)
    boundary: Endpoints | None = None
    name: str = "scene"
    source: str = ""
    description: str = ""
    scheme: str | None = None
    ranges: Mapping[str, str] = field(default_factory=dict)
    digest: str = ""

    def __post_init__(self):
        _check_common(self)
        self.order = check_integer("order", self.order)

    @cached_property
    def system(self) -> HigherOrderSystem:
        return HigherOrderSystem(self.lagrangian, self.n, self.order, dict(self.params),
                                 name=self.name)

    def resolve(self, overrides=None) -> HigherRunConfig:
        """Parameters, ``t0``, ``tau0``, ``t_end`` with ``overrides`` applied."""
        overrides = dict(overrides or {})
        settings = {k: overrides.pop(k) for k in RUN_SETTINGS if k in overrides}
        params = check_parameter_values(overrides, dict(self.params),
                                        owner=f"scene {self.name!r}", ranges=self.ranges)
        values = {"t0": self.t0, "tau0": self.tau0, "t_end": self.t_end, **settings}
        for key, value in values.items():
            check_real(key, value)
        if values["t_end"] <= values["t0"]:
            raise InputError(f"t_end must be > t0 = {values['t0']!r}, got {values['t_end']!r}")
        check_step(values["tau0"], float(values["t0"]), float(values["t_end"]))
        return HigherRunConfig(params=params, **{k: float(v) for k, v in values.items()})

    def start(self, config: HigherRunConfig) -> tuple[np.ndarray, np.ndarray]:
        """The ``2 l`` start nodes of a march: the exact motion ``tau0`` apart from ``t0``."""
        t = config.t0 + config.tau0 * np.arange(2 * self.order)
        return t, self.exact_motion(t, config.params)

    def ends(self, config: HigherRunConfig, nodes: int, t_span):
        """The ``l`` fixed nodes at each end of the uniform grid of ``nodes`` nodes on
        ``t_span``, on the exact motion."""
        grid = np.linspace(t_span[0], t_span[1], nodes)
        l = self.order  # noqa: E741 (l is the order, as in the paper)
        q = self.exact_motion(grid, config.params)
        return grid[:l], q[:l], grid[-l:], q[-l:]

    def exact_motion(self, t, params):
        """The scene's exact motion ``q(t)`` at the times ``t``, shape ``(N, n)``."""
        return np.asarray(self.exact(np.asarray(t, float), **params), float).reshape(
            np.size(t), self.n)

    def boundary_nodes(self, nodes: int | None = None) -> int:
        """The nodes of a fixed-endpoint grid: ``nodes``, else the scene's, else
        `BOUNDARY_NODES`."""
        return nodes or (self.boundary and self.boundary.nodes) or BOUNDARY_NODES

    def exact_positions(self, config: HigherRunConfig) -> Callable:
        """The exact motion of a run as ``exact(t) -> q`` (rows), for the accuracy check."""
        return lambda t: self.exact_motion(t, config.params)


def _check_common(scene) -> None:
    """What every scene must be: a scheme name or none, ``boundary`` an `Endpoints`,
    ``n`` a size that fits in memory, ``params`` a mapping of names to finite numbers (a list
    was taken and failed later), ``ranges`` intervals holding the defaults."""
    _check_scheme_name(scene.scheme)
    scene.boundary = as_settings(f"scene {scene.name!r}: boundary", scene.boundary, Endpoints)
    scene.n = check_degrees(scene.n)
    owner = f"scene {scene.name!r}"
    if not isinstance(scene.params, Mapping) or not all(isinstance(k, str)
                                                        for k in scene.params):
        raise InputError(f"{owner}: params must be a dict of parameter names to numbers, got "
                         f"{scene.params!r}")
    scene.params = check_parameter_values(dict(scene.params), dict(scene.params), owner=owner)
    scene.ranges = check_parameter_ranges(scene.ranges, scene.params, owner=owner)
    check_parameter_values({}, scene.params, owner=owner, ranges=scene.ranges)
    if not isinstance(getattr(scene, "invariants", {}), Mapping):
        raise InputError(f"{owner}: invariants must be a dict of names to functions, got "
                         f"{scene.invariants!r}")
    for key in ("exact",):
        value = getattr(scene, key, None)
        if value is not None and not callable(value):
            raise InputError(f"{owner}: {key} must be a function or None, got {value!r}")


def _check_scheme_name(scheme) -> None:
    """A scene's declared scheme is a name (which names exist is the command line's to check:
    the scheme rules live in ``discrete/``, above this module)."""
    if scheme is not None and (not isinstance(scheme, str) or not scheme.strip()):
        raise InputError(f"scene scheme must be a scheme name such as 'fixed', got {scheme!r}")
