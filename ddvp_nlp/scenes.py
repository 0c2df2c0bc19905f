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

import contextlib
import hashlib
import importlib.util
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from .errors import InputError
from .physics.hamiltonian import HamiltonianSystem
from .physics.higher import HigherOrderSystem
from .physics.lagrangian import Lagrangian, LagrangianSystem
from .validation import (
    check_degrees,
    check_integer,
    check_parameter_ranges,
    check_parameter_values,
    check_real,
    check_state,
    check_step,
    read_limited,
)

RUN_SETTINGS = ("t0", "tau0", "t_end")
STATE_SETTINGS = ("q0", "p0", "v0")
BOUNDARY_SETTINGS = ("q_start", "q_end", "t0", "t_end")
VECTOR_SETTINGS = ("q0", "p0", "v0", "q_start", "q_end")


@dataclass(frozen=True)
class Endpoints:
    """A scene's default fixed-endpoint problem (``ddvp bvp``): the end positions (not for a
    higher-order scene, whose ends come from its exact motion), the time span and the node
    count. Any field left ``None`` falls back to the scene's ``t0``, ``t_end`` or 101 nodes."""

    q_start: object = None
    q_end: object = None
    t_span: tuple | None = None
    nodes: int | None = None


@dataclass(frozen=True)
class PeriodicSettings:
    """A scene's defaults for ``ddvp periodic`` (``solvers/periodic``).

    Attributes:
        section: the phase condition on node 0, ``"NAME=VALUE"``.
        energy: the default prescribed energy.
        nodes: the default number of intervals.
        start: ``(q, p)``, the direction along which the section's point at ``energy`` is
            looked for.
        integrals: first integrals besides ``H`` whose flows are symmetries.
        angles: angle coordinates (``("q1",)``), which may close with whole turns.
        families: further families by name, each its own ``PeriodicSettings`` (section and
            start; read by ``scripts/periodic_page.py``).
        guess: optional ``guess(energy, **params) -> {"t", "q", "p"}``, one period of a start
            near the orbit at ``energy``, used when no guess is given (where no ray from the
            origin through the orbit makes the section's point, as about a Lagrange point).
    """

    section: str = "p1=0"
    energy: float | None = None
    nodes: int = 200
    start: tuple | None = None
    integrals: tuple = ()
    angles: tuple = ()
    families: Mapping[str, PeriodicSettings] = field(default_factory=dict)
    guess: Callable[..., Mapping] | None = None


def _check_settings(owner: str, name: str, value, kind):
    """A scene's ``boundary``/``periodic`` setting is ``None`` or a ``kind``; anything else
    (a dict, the shape these had before) is refused by name."""
    if value is not None and not isinstance(value, kind):
        raise InputError(f"scene {owner!r}: {name} must be {kind.__name__}(...) or None, got "
                         f"{value!r}")


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
        boundary: optional default fixed-endpoint data, an `Endpoints`.
        name, description: set from the file name and docstring when loaded.
        source: the name or path it was loaded from (empty for a scene made in Python); grid
            tasks reload the scene from it in their own process.
        periodic: optional defaults of ``ddvp periodic``, a `PeriodicSettings`.
        scheme: optional scheme ``ddvp march`` and ``ddvp bvp`` use when ``--scheme`` is not
            given (default ``None``: the paper's ``vddvp``); ``ddvp scenes`` shows it.
        ranges: optional intervals of the parameters where the scene means something, e.g.
            ``{"e": "[0, 1)"}`` for an eccentricity; a value outside is refused by name before
            anything is built.
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
    v0: object = None
    periodic: PeriodicSettings | None = None
    scheme: str | None = None
    ranges: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self):
        _check_common(self)
        _check_settings(self.name, "boundary", self.boundary, Endpoints)
        _check_settings(self.name, "periodic", self.periodic, PeriodicSettings)
        for key in ("q0", "tau0", "t_end"):
            if getattr(self, key) is None:
                raise InputError(f"scene needs {key}")
        if (self.p0 is None) == (self.v0 is None):
            raise InputError("scene needs exactly one of p0 and v0")
        if self.v0 is not None and not isinstance(self.hamiltonian, Lagrangian):
            raise InputError("v0 is for a scene declared by Lagrangian(L); give p0")

    @cached_property
    def system(self) -> HamiltonianSystem:
        if isinstance(self.hamiltonian, Lagrangian):
            return LagrangianSystem(self.hamiltonian.function, self.n, dict(self.params),
                                    name=self.name)
        return HamiltonianSystem(self.hamiltonian, self.n, dict(self.params), name=self.name)

    def _split_parameters(self, overrides, settings_names):
        overrides = dict(overrides or {})
        settings = {k: overrides.pop(k) for k in settings_names if k in overrides}
        unknown = sorted(set(overrides) - set(self.params))
        if unknown:
            known = ", ".join([*self.params, *settings_names])
            raise InputError(f"scene {self.name!r} has no parameter {unknown[0]!r} "
                             f"(it has: {known})")
        return check_parameter_values(overrides, self.params, owner=f"scene {self.name!r}",
                                      ranges=self.ranges), settings

    def resolve_boundary(self, overrides: Mapping[str, object] | None = None,
                         nodes: int | None = None) -> BoundaryConfig:
        """Fixed-endpoint data: the scene's ``boundary`` with ``overrides`` (parameters,
        ``q_start``, ``q_end``, ``t0``, ``t_end``) and ``nodes`` applied."""
        params, settings = self._split_parameters(overrides, BOUNDARY_SETTINGS)
        data = self.boundary or Endpoints()
        if self.boundary is None and not {"q_start", "q_end"} <= set(settings):
            raise InputError(f"scene {self.name!r} declares no fixed-endpoint data: give "
                             "q_start, q_end, t0 and t_end (--set NAME=VALUE) and --nodes")
        t_span = data.t_span or (self.t0, self.t_end)
        t0 = settings.get("t0", t_span[0])
        t1 = settings.get("t_end", t_span[1])
        return BoundaryConfig(params=params,
                              q_start=np.atleast_1d(np.asarray(settings.get(
                                  "q_start", data.q_start), dtype=float)),
                              q_end=np.atleast_1d(np.asarray(settings.get(
                                  "q_end", data.q_end), dtype=float)),
                              t_span=(float(t0), float(t1)),
                              nodes=nodes if nodes is not None else (data.nodes or 101))

    def resolve(self, overrides: Mapping[str, object] | None = None) -> RunConfig:
        """Defaults with ``overrides`` applied: parameters, ``t0``, ``tau0``, ``t_end``, ``q0``,
        ``p0``. Unknown names are an error that lists the known ones."""
        lagrangian = isinstance(self.hamiltonian, Lagrangian)
        names = (*RUN_SETTINGS, *(STATE_SETTINGS if lagrangian else STATE_SETTINGS[:2]))
        params, settings = self._split_parameters(overrides, names)
        q0 = settings.get("q0", self.q0)
        if "p0" in settings and "v0" in settings:
            raise InputError("give p0 or v0, not both")
        p0 = settings.get("p0", None if "v0" in settings else self.p0)
        v0 = settings.get("v0", None if "p0" in settings else self.v0)
        values = {k: settings.get(k, getattr(self, k)) for k in RUN_SETTINGS}
        for k, v in values.items():
            check_real(k, v)
        if values["t_end"] <= values["t0"]:
            raise InputError(f"t_end must be > t0 = {values['t0']!r}, got {values['t_end']!r}")
        check_step(values["tau0"], float(values["t0"]), float(values["t_end"]))
        q0, p0, v0 = (None if x is None else self._start_value(name, x, params)
                      for name, x in (("q0", q0), ("p0", p0), ("v0", v0)))
        return RunConfig(params=params, q0=q0, p0=p0, v0=v0,
                         **{k: float(v) for k, v in values.items()})

    def march(self, t_end: float | None = None, *, overrides: Mapping[str, object] | None = None,
              **options):
        """``march`` from this scene's defaults (``resolve(overrides)``: parameters, start,
        ``t0``, ``tau0``, ``t_end``; ``t_end`` here wins), its default scheme, and ``options``
        passed on (``steps=``, ``accuracy=``, ``compilation=``, ``output=``, ``scheme=``...)."""
        from .solvers.march import march  # a facade: scenes sit below the solvers

        config = self.resolve(overrides)
        options.setdefault("scheme", self.scheme or "vddvp")
        options.setdefault("tau0", config.tau0)
        return march(self.system, config.q0, config.p0, (config.t0, t_end or config.t_end),
                     v0=config.v0, params=config.params, **options)

    def solve_bvp(self, *, overrides: Mapping[str, object] | None = None,
                  nodes: int | None = None, **options):
        """``solve_bvp`` on this scene's fixed-endpoint data (``resolve_boundary``) and default
        scheme, ``options`` passed on."""
        from .solvers.bvp import solve_bvp  # a facade: scenes sit below the solvers

        data = self.resolve_boundary(overrides, nodes)
        options.setdefault("scheme", self.scheme or "vddvp")
        return solve_bvp(self.system, data.q_start, data.q_end, data.t_span, nodes=data.nodes,
                         params=data.params, **options)

    def solve_periodic(self, energy: float | None = None, *, nodes: int | None = None,
                       overrides: Mapping[str, object] | None = None, **options):
        """``solve_periodic`` with this scene's periodic defaults (``PeriodicSettings``:
        energy, nodes, section, start, integrals, angles, the guess function) and its default
        scheme, ``options`` passed on. (Named so because ``periodic`` is the settings field.)"""
        from .solvers.periodic import solve_periodic  # a facade: scenes sit below the solvers

        settings = self.periodic or PeriodicSettings()
        energy = settings.energy if energy is None else energy
        if energy is None:
            raise InputError(f"scene {self.name!r} declares no periodic energy: give energy=")
        params, _ = self._split_parameters(overrides, ())
        if settings.guess is not None:
            options.setdefault("guess", settings.guess(energy, **params))
        for name in ("section", "start", "integrals", "angles"):
            if getattr(settings, name) is not None:
                options.setdefault(name, getattr(settings, name))
        options.setdefault("scheme", self.scheme or "vddvp")
        return solve_periodic(self.system, energy=energy, nodes=nodes or settings.nodes,
                              params=params, **options)

    def _start_value(self, name: str, value, params: dict) -> np.ndarray:
        """The scene's ``q0``, ``p0`` or ``v0`` (a function of the parameters, or a value) as a
        finite real vector of length ``n``; a function that raises is named with the values."""
        if callable(value):
            try:
                value = value(**params)
            except SceneCodeError as exc:
                raise InputError(f"scene {self.name!r}: {name} cannot be computed for "
                                 f"{_shown(params)}: {exc.reason.removeprefix('raised ')} "
                                 f"({exc.where})") from None
            except Exception as exc:
                raise InputError(f"scene {self.name!r}: {name} cannot be computed for "
                                 f"{_shown(params)}: {type(exc).__name__}: {exc}") from None
        return check_state(f"scene {self.name!r}: {name}", value, self.n)


@dataclass
class RunConfig:
    """Resolved values of one run of a scene."""

    params: dict[str, float]
    q0: np.ndarray
    p0: np.ndarray | None
    t0: float
    tau0: float
    t_end: float
    v0: np.ndarray | None = None

    def as_dict(self) -> dict:
        start = {"p0": self.p0.tolist()} if self.p0 is not None else {"v0": self.v0.tolist()}
        return {**self.params, "q0": self.q0.tolist(), **start, "t0": self.t0,
                "tau0": self.tau0, "t_end": self.t_end}


@dataclass
class HigherRunConfig:
    """Resolved values of one run of a higher-order scene."""

    params: dict[str, float]
    t0: float
    tau0: float
    t_end: float

    def as_dict(self) -> dict:
        """The resolved settings as plain values (what a run folder's name is hashed from)."""
        return {"params": dict(self.params), "t0": self.t0, "tau0": self.tau0,
                "t_end": self.t_end}


@dataclass
class BoundaryConfig:
    """Resolved fixed-endpoint data of a scene."""

    params: dict[str, float]
    q_start: np.ndarray
    q_end: np.ndarray
    t_span: tuple[float, float]
    nodes: int

    def as_dict(self) -> dict:
        return {**self.params, "q_start": self.q_start.tolist(), "q_end": self.q_end.tolist(),
                "t0": self.t_span[0], "t_end": self.t_span[1], "nodes": self.nodes}


def scene_folder() -> Path:
    """The folder of the built-in scenes: installed package data, or the source tree's
    ``problems/`` when running from a checkout."""
    try:
        import ddvp_nlp.problems as installed
        return Path(installed.__file__).parent
    except ImportError:
        return Path(__file__).resolve().parent.parent / "problems"


def list_scenes() -> list[str]:
    return sorted(p.stem for p in scene_folder().glob("*.py") if not p.stem.startswith("_"))


def scene_file(name_or_path: str) -> Path:
    """The file of a built-in scene (by name) or of a scene file (by path), checked."""
    if not isinstance(name_or_path, str) or not name_or_path:
        raise InputError(f"scene must be a name or a path, got {name_or_path!r}")
    looks_like_path = name_or_path.endswith(".py") or "/" in name_or_path or "\\" in name_or_path
    if looks_like_path:
        path = Path(name_or_path)
        if not path.is_file():
            raise InputError(f"scene file {name_or_path!r} does not exist")
        if path.suffix != ".py":
            raise InputError(f"scene file {name_or_path!r} is not a Python file (.py)")
        return path
    if name_or_path not in list_scenes():
        raise InputError(f"unknown scene {name_or_path!r} (built-in scenes: "
                         f"{', '.join(list_scenes())})")
    return scene_folder() / f"{name_or_path}.py"


def scene_digest(name_or_path: str) -> str:
    """SHA-256 of the scene's file: what a grid row was computed from, so that a resumed grid
    reuses a row only for the same file, and a worker refuses a different one."""
    return hashlib.sha256(read_limited(scene_file(name_or_path), SCENE_FILE_LIMIT,
                                       what="scene file")).hexdigest()


def load_scene(name_or_path: str, *, digest: str | None = None) -> Scene:
    """A built-in scene by name, or the scene defined in a Python file; with ``digest``, only
    if the file's SHA-256 is that (a worker of a grid loads the file the grid was planned on).

    The file's code runs bounded (`scene_code`): whatever it raises (``SystemExit``,
    ``GeneratorExit``, any ``BaseException`` but ``KeyboardInterrupt``), an ``os._exit``, or a
    run past the time limit is an `InputError` naming the file and the line; so is
    every later call of the scene's functions (``H`` or ``L``, ``exact``, the invariants, the
    start functions), which are checked once on the scene's own defaults here."""
    path = scene_file(name_or_path)
    name = path.stem
    source = read_limited(path, SCENE_FILE_LIMIT, what="scene file")
    if digest is not None and hashlib.sha256(source).hexdigest() != digest:
        raise InputError(f"scene file {str(path)!r} is not the one this grid was planned with "
                         "(its content differs): a worker has another file of that name, or it "
                         "changed since")
    spec = importlib.util.spec_from_file_location(f"ddvp_scene_{name}", path)
    module = importlib.util.module_from_spec(spec)
    with scene_code(path, "loading the file"):
        code = compile(source, str(path), "exec")
        exec(code, module.__dict__)  # noqa: S102 - the scene file the user named
    scene = module.__dict__.get("scene")
    if not isinstance(scene, (Scene, HigherOrderScene)):
        raise InputError(f"scene file {str(path)!r} defines no `scene = Scene(...)`")
    scene.name = name
    scene.source = name_or_path  # how another process loads the same scene
    doc = module.__dict__.get("__doc__")
    scene.description = doc.strip().splitlines()[0] if isinstance(doc, str) and doc.strip() \
        else ""
    _guard_functions(scene, path)
    _probe(scene, path)
    return scene


# Largest scene file read: a scene is a page of Python.
SCENE_FILE_LIMIT = 4 << 20
# Seconds a scene's code may run in one call (loading the file, building H, one evaluation of
# exact or an invariant, plus SCENE_SECONDS_PER_VALUE for each value of its array arguments);
# $DDVP_SCENE_TIME_LIMIT overrides the base.
SCENE_SECONDS = 20.0
SCENE_SECONDS_PER_VALUE = 2e-6
SCENE_SECONDS_VARIABLE = "DDVP_SCENE_TIME_LIMIT"


class _SceneTimeout(BaseException):
    """Raised by the alarm in a scene's code that ran past its time limit."""


class _SceneExit(BaseException):
    """Raised in place of ``os._exit``/``os.abort`` called by a scene's code."""


class _GuardState:
    depth = 0


def scene_seconds() -> float:
    """The base time limit of a scene's code (``$DDVP_SCENE_TIME_LIMIT`` or the default)."""
    import math
    import os

    text = os.environ.get(SCENE_SECONDS_VARIABLE, "")
    try:
        value = float(text) if text.strip() else SCENE_SECONDS
    except ValueError:
        value = SCENE_SECONDS
    return value if math.isfinite(value) and value > 0 else SCENE_SECONDS


@contextlib.contextmanager
def scene_code(path, what: str, size: int = 0):
    """Run a scene's code: any exception it raises but ``KeyboardInterrupt`` (and an
    `InputError` of ddvp's own checks) becomes an `InputError` with the file,
    the line and the message; ``os._exit``/``os.abort`` raise instead of ending the process;
    past ``scene_seconds() + size * SCENE_SECONDS_PER_VALUE`` seconds an alarm ends it (in the
    main thread; worker threads of a grid have no alarm)."""
    import os
    import signal
    import threading

    outer = _GuardState.depth == 0 and threading.current_thread() is threading.main_thread()
    limit = scene_seconds() + size * SCENE_SECONDS_PER_VALUE
    _GuardState.depth += 1
    saved = (os._exit, os.abort)
    if outer:
        os._exit, os.abort = _refused_exit, _refused_abort
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, limit)
    try:
        yield
    except (KeyboardInterrupt, SceneCodeError, _Passed):
        raise
    except InputError as exc:  # a check of ddvp's own, called by the scene: say where
        where, _ = _describe(path, what, exc, limit)
        if "line" not in where:
            raise
        raise SceneCodeError(f"{where}: {exc}", where=where, reason=str(exc)) from None
    except BaseException as exc:  # noqa: B036 - a scene must not end the command its own way
        where, reason = _describe(path, what, exc, limit)
        raise SceneCodeError(f"{where}: {what} {reason}", where=where, reason=reason) from None
    finally:
        _GuardState.depth -= 1
        if outer:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
            os._exit, os.abort = saved


def _alarm(signum, frame):
    raise _SceneTimeout


def _refused_exit(code=0):
    raise _SceneExit(f"os._exit({code!r})")


def _refused_abort():
    raise _SceneExit("os.abort()")


class SceneCodeError(InputError):
    """A scene's code failed: ``where`` (the file and the line) and ``reason`` (what it did)."""

    def __init__(self, message: str, *, where: str, reason: str):
        super().__init__(message)
        self.where, self.reason = where, reason


def _describe(path, what: str, exc: BaseException, limit: float) -> tuple[str, str]:
    """``(where, reason)``: ``scene file PATH, line N`` (the deepest line of the scene file in
    the traceback) and what happened in words."""
    import traceback

    line = None
    wanted = str(Path(path).resolve())
    for frame in traceback.extract_tb(exc.__traceback__):
        if str(Path(frame.filename).resolve()) == wanted:
            line = frame.lineno
    where = f"scene file {str(path)!r}" + (f", line {line}" if line else "")
    if isinstance(exc, _SceneTimeout):
        return where, (f"did not return within {limit:.3g} s (the limit of a scene's code; "
                       f"${SCENE_SECONDS_VARIABLE} sets it)")
    if isinstance(exc, SystemExit):
        return where, f"called sys.exit({exc.code!r}); a scene may not end the command"
    if isinstance(exc, _SceneExit):
        return where, f"called {exc}; a scene may not end the command"
    return where, f"raised {type(exc).__name__}: {exc}"


def _guarded(function, path, what: str, *, passes=()):
    """``function`` run under `scene_code` at every call; exceptions of ``passes`` (the
    ``ValueError`` an ``exact`` raises for a start it does not cover) pass as they are."""
    import functools

    if not callable(function) or getattr(function, "__ddvp_guarded__", False):
        return function

    @functools.wraps(function)
    def guarded(*args, **kwargs):
        size = sum(int(np.size(a)) for a in args if isinstance(a, np.ndarray))
        try:
            with scene_code(path, what, size):
                try:
                    return function(*args, **kwargs)
                except passes as exc:
                    raise _Passed(exc) from None
        except _Passed as passed:
            raise passed.args[0] from None

    guarded.__ddvp_guarded__ = True
    return guarded


class _Passed(InputError):
    """Carries an allowed exception of a scene's function through `scene_code`."""


def _guard_functions(scene, path) -> None:
    """Every function of ``scene`` replaced by its guarded form (`_guarded`)."""
    if isinstance(scene, HigherOrderScene):
        scene.lagrangian = _guarded(scene.lagrangian, path, "L")
        scene.exact = _guarded(scene.exact, path, "exact")
        return
    if isinstance(scene.hamiltonian, Lagrangian):
        scene.hamiltonian.function = _guarded(scene.hamiltonian.function, path, "L")
    else:
        scene.hamiltonian = _guarded(scene.hamiltonian, path, "H")
    scene.exact = _guarded(scene.exact, path, "exact", passes=(ValueError,))
    scene.invariants = {name: _guarded(f, path, f"invariant {name!r}")
                        for name, f in scene.invariants.items()}
    for key in ("q0", "p0", "v0"):
        setattr(scene, key, _guarded(getattr(scene, key), path, key))


def _probe(scene, path) -> None:
    """The scene's functions called once on its own defaults, so that one that raises, hangs
    or returns what is not an array of numbers is refused now, not after a long run: ``H``
    (or ``L``) built symbolically, ``exact`` and every invariant at the start."""
    scene.system  # noqa: B018 - builds H (or L) on symbols, under its guard
    if isinstance(scene, HigherOrderScene):
        config = scene.resolve({})
        scene.exact_motion(np.array([config.t0, config.t0 + config.tau0]), config.params)
        return
    config = scene.resolve({})
    if config.p0 is None:
        return
    q, p = config.q0[None, :], config.p0[None, :]
    for name, invariant in scene.invariants.items():
        value = invariant(q, p, **config.params)
        check_invariant_value(scene.name, name, value, 1)
    if scene.exact is not None:
        try:
            scene.exact(np.array([config.t0, config.t0 + config.tau0]), config.q0, config.p0,
                        config.t0, **config.params)
        except SceneCodeError:
            raise
        except ValueError:  # a start it does not cover: the studies use a reference instead
            pass


def check_invariant_value(scene: str, name: str, value, count: int) -> np.ndarray:
    """An invariant's value: ``count`` finite-or-not real numbers."""
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"scene {scene!r}: invariant {name!r} returned "
                         f"{type(value).__name__} {str(value)[:60]!r}, not {count} real "
                         "numbers") from None
    if array.size != count:
        raise InputError(f"scene {scene!r}: invariant {name!r} returned {array.size} values "
                         f"for {count} states")
    return array


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


def _shown(params: dict) -> str:
    return ", ".join(f"{k} = {v:g}" for k, v in params.items()) or "the defaults"


def _check_common(scene) -> None:
    """What every scene must be: a scheme name or none, ``boundary`` an `Endpoints`,
    ``n`` a size that fits in memory, ``params`` a mapping of names to finite numbers (a list
    was taken and failed later), ``ranges`` intervals holding the defaults."""
    _check_scheme_name(scene.scheme)
    _check_settings(scene.name, "boundary", scene.boundary, Endpoints)
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
