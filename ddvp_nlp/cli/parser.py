"""The ``ddvp`` command line: one parser per command; method lists and scheme names come from
the registries, not typed in."""

from __future__ import annotations

import argparse

from ..discrete import CLOCKS, RULES, Scheme
from ..errors import InputError
from ..scenes import BOUNDARY_NODES, VECTOR_SETTINGS
from .arguments import api_default, periodic_nodes


def shown(value) -> str:
    """A default as the help text shows it."""
    if value is None:
        return "none"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def parse_settings(items: list[str]) -> dict:
    """``NAME=VALUE`` pairs; ``q0``, ``p0``, ``q_start``, ``q_end`` take comma-separated lists."""
    from ..validation import check_unique_settings

    check_unique_settings(items)
    settings = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise InputError(f"--set expects NAME=VALUE, got {item!r}")
        try:
            if name in VECTOR_SETTINGS:
                value = [float(v) for v in text.split(",")]
            else:
                value = float(text)
        except ValueError:
            raise InputError(f"--set {name}: value {text!r} is not a number") from None
        settings[name] = value
    return settings


# The compared methods ``ddvp march --method`` runs: every method of the comparison
# (``studies/methods.py``'s ``METHODS``) but the energy rules, in its order. Written out so
# that a march's parser does not import every baseline to list them (0.04 s of each ``ddvp
# march``); a test holds it equal to the registry.
COMPARED_METHODS = ("midpoint", "stormer_verlet", "leapfrog", "verlet_adaptive", "avf", "rk4",
                    "dop853", "lee_left", "rattle", "shake")


def _scheme_arguments(parser: argparse.ArgumentParser, command: str, methods: tuple = (), *,
                      scene_optional: bool = False) -> None:
    parser.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file",
                        **({"nargs": "?", "default": None} if scene_optional else {}))
    parser.add_argument("--scheme", default=None, metavar="{" + ",".join(RULES) + "}",
                        help=f"energy rule: {', '.join(RULES)} (default: the scene's, shown by "
                        f"`ddvp scenes`, else {Scheme().rule}, the paper's)")
    if methods:
        parser.add_argument("--method", default=None, choices=methods,
                            help="march with a compared method instead of an energy rule, its "
                                 "knob tau0 (dop853: rtol = atol = --tol): "
                                 f"{', '.join(methods)}")
    alpha, clock = api_default(command, "alpha"), api_default(command, "clock")
    parser.add_argument("--alpha", type=float, default=alpha,
                        help=f"weight alpha of the scheme, beta = 1 - alpha (default: "
                             f"{shown(alpha)})")
    parser.add_argument("--clock", default=clock, choices=CLOCKS,
                        help=f"time at which H is evaluated on an interval (default: {clock})")
    parser.add_argument("--set", dest="settings", action="append", default=[],
                        metavar="NAME=VALUE",
                        help="override a scene parameter or a setting: march: t0, tau0, t_end "
                             "and the initial state q0 with p0 (or v0, the first velocity, for "
                             "a scene declared by its Lagrangian; a higher-order scene starts "
                             "on its exact motion); bvp: q_start, q_end, t0, t_end; vectors "
                             "as comma lists, e.g. q0=1,0; repeatable")
    parser.add_argument("--out", default=None,
                        help="output folder (default: runs/SCENE-SCHEME, runs/SCENE-bvp-SCHEME "
                             "for bvp; with --set (bvp: or --nodes) a short hash of the resolved "
                             "settings is appended, e.g. runs/kepler-vddvp-1a2b3c4d)")
    tol = api_default(command, "tol")
    parser.add_argument("--tol", type=float, default=tol,
                        help=f"acceptance tolerance of the unscaled residuals (default: "
                             f"{shown(tol)})")


def _run_bounds(parser: argparse.ArgumentParser, *, defaults: bool) -> None:
    """Per-run bounds and options shared by the grid commands (``defaults=False``: ``None``,
    so a grid file's bounds apply unless given here)."""
    steps, seconds = api_default("stress", "max_steps"), api_default("stress", "time_limit")
    parser.add_argument("--max-steps", type=int, default=steps if defaults else None,
                        help=f"bound on the steps of each run (default: {shown(steps)})")
    parser.add_argument("--time-limit", type=float, default=seconds if defaults else None,
                        help=f"bound in seconds on each run, wall time (default: "
                             f"{shown(seconds)})")
    parser.add_argument("--no-compile", action="store_true",
                        help="run the compiled methods on CasADi's virtual machine instead")
    _progress_arguments(parser, "a line per finished run")


def _progress_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """``--progress/--no-progress``, the same on every command: ``None`` (neither given) is
    the command's default."""
    from ..progress import PLAIN_LINE_SECONDS

    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help=f"progress on stderr ({what}): a bar on a terminal, else a plain "
                             f"line every {PLAIN_LINE_SECONDS:g} s; --no-progress for none")


def _grid_arguments(parser: argparse.ArgumentParser, workers_default: str) -> None:
    parser.add_argument("--workers", type=int, default=None,
                        help=f"local worker processes (default: {workers_default})")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run the tasks on this Dask scheduler, e.g. tcp://host:8786 "
                             "(default: $DDVP_SCHEDULER, else local)")
    _cluster_argument(parser)


def _cluster_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cluster", default=None, metavar="SPEC|FILE",
                        help="start a Dask cluster for this run and run on it: "
                             "local:workers=N[,threads=T] or slurm:cores=C,memory=M,"
                             "walltime=HH:MM:SS,jobs=J[,queue=Q,account=A,processes=P,"
                             "job_extra=L1;L2], or a TOML file with a [cluster] table "
                             "(runner/cluster.py; slurm needs pip install 'ddvp-nlp[cluster]')")


class VersionAction(argparse.Action):
    """``--version``: argparse's own, but the version is looked up when asked for, not while
    the parser is built (importlib.metadata, 0.03 s of every command's start)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show program's version number and exit"):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from .. import __version__

        print(f"{parser.prog} {__version__}")  # on stdout, as argparse's
        parser.exit()


def parse_arguments(parser: argparse.ArgumentParser, argv: list[str] | None):
    """``parser.parse_args(argv)``, except that an unknown option of a command is refused with
    that command's usage (argparse leaves leftovers to the top level, whose usage lists only
    the commands). Exits 2 with the message, as argparse does."""
    args, extra = parser.parse_known_args(argv)
    if extra:
        command = getattr(parser, "commands", {}).get(vars(args).get("command"), parser)
        hint = setting_hint(command, args, extra)
        if hint is not None:  # one line, not the usage: the user knows the command
            command.exit(2, f"{command.prog}: error: {hint}\n")
        command.error(f"unrecognized arguments: {' '.join(extra)}")
    return args


def setting_hint(command: argparse.ArgumentParser, args, extra: list[str]) -> str | None:
    """For an unknown ``--NAME [VALUE]`` that is a scene setting (``t0``, ``tau0``, ``q0``
    ...) or a parameter of the scene named on the command line: how to give it with
    ``--set``. For another unknown option: the command's options closest to it, if any."""
    import difflib
    import re

    from ..scenes import BOUNDARY_SETTINGS, RUN_SETTINGS, STATE_SETTINGS

    option = next((item for item in extra if item.startswith("--")), None)
    if option is None:
        return None
    flag, _, value = option.partition("=")
    if not value:
        after = extra[extra.index(option) + 1:extra.index(option) + 2]
        value = after[0] if after and not after[0].startswith("-") else "VALUE"
    name = flag[2:].replace("-", "_")
    # the options as the usage line names them (argparse keeps its actions private)
    flags = sorted(set(re.findall(r"--[a-z][a-z0-9-]*", command.format_usage())))
    takes_set = "--set" in flags
    names = {*RUN_SETTINGS, *STATE_SETTINGS, *BOUNDARY_SETTINGS, *_scene_parameters(args)}
    if takes_set and name in names:
        return (f"{flag} is not an option of {command.prog}: scene settings and parameters "
                f"are given with --set, e.g. --set {name}={value} (see `ddvp scenes`)")
    close = difflib.get_close_matches(flag, flags, n=3, cutoff=0.75)
    if close:
        return f"unrecognized option {flag}; did you mean {' or '.join(close)}?"
    return None


def _scene_parameters(args) -> tuple:
    """The parameter names of the built-in scene named on the command line (none for a scene
    file, whose code is not run to make a message, or an unknown name)."""
    from ..scenes import list_scenes, load_scene

    scene = vars(args).get("scene")  # the parsed words: a command may have no scene
    if not isinstance(scene, str) or scene not in list_scenes():
        return ()
    try:
        return tuple(load_scene(scene).params)
    except InputError:
        return ()


# Each command: its one-line help and the function that adds its options.
COMMAND_HELP = {
    "scenes": "list the built-in scenes: parameters, initial state, fixed-endpoint data and "
              "default scheme",
    "march": "solve an initial-value problem step by step",
    "bvp": "solve a fixed-endpoint problem on the whole grid",
    "compare": "work-precision: error against run time for every method on a scene",
    "stress": "run every method on the stiff and extreme cases; say where each breaks",
    "sweep": "run your own grid of settings x methods, locally or on a Dask cluster",
    "reproduce": "figures and report.md comparing the paper's claims with measurements",
    "periodic": "find a periodic orbit at a prescribed energy (or a family of them)",
    "poincare": "a Poincare section at a fixed energy: many orbits marched together",
    "chaos": "a chaos map (MEGNO, largest Lyapunov exponent) over a grid on a section",
}


# `build_parser(NO_COMMAND)`: the commands' names and help without any command's options, all
# that `ddvp --version`, `ddvp --help` and `ddvp` alone need (with every command's options,
# `ddvp --version` loaded every solver family and scipy.interpolate: 1.35 s of CPU).
NO_COMMAND = ""


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``ddvp`` parser: every command with its help, and the options of ``command`` (of
    every command if ``None``, of none if `NO_COMMAND`). A command's options take their
    defaults from the API, which may load the modules behind them: building only the one a run
    needs keeps ``ddvp march`` from loading the studies."""
    parser = argparse.ArgumentParser(
        prog="ddvp", description="Variable-time-step discrete mechanics (difference discrete "
                                 "variational principle) on CasADi.")
    parser.add_argument("--version", action=VersionAction)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                     help="one of the commands below; `ddvp COMMAND --help` "
                                          "lists its options")
    options = {"scenes": lambda sub: None, "march": _march_command, "bvp": _bvp_command,
               "compare": _compare_command, "stress": _stress_command,
               "sweep": _sweep_command, "reproduce": _reproduce_command,
               "periodic": _periodic_command, "poincare": _poincare_command,
               "chaos": _chaos_command}
    for name, words in COMMAND_HELP.items():
        sub = commands.add_parser(name, help=words)
        if command is None or command == name:
            options[name](sub)
    parser.commands = dict(commands.choices)  # each command's parser, for its own usage
    return parser


def command_in(argv: list[str]) -> str:
    """The command an argument list names (its first word that is not an option), else
    `NO_COMMAND`."""
    return next((word for word in argv if not word.startswith("-")), NO_COMMAND)


def _poincare_command(poincare: argparse.ArgumentParser) -> None:
    poincare.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    poincare.add_argument("--energy", type=float, required=True, help="the energy E")
    # defaults measured to give a dense section in a few seconds: Henon-Heiles at E = 1/8, 50
    # orbits to t = 2000, 15214 crossings in 2.4 s wall on 2 shared cores (README)
    value = {name: api_default("poincare", name) for name in
             ("orbits", "section", "direction", "t_end", "seed", "workers")}
    poincare.add_argument("--orbits", type=int, default=value["orbits"],
                          help=f"number of orbits M (default {value['orbits']})")
    poincare.add_argument("--section", default=value["section"], metavar="NAME=VALUE",
                          help=f"the section, NAME in q1..qn (default {value['section']})")
    poincare.add_argument("--direction", default=value["direction"], choices=("+", "-"),
                          help="crossings with the section coordinate increasing (+) or "
                               f"decreasing (-) (default {value['direction']})")
    poincare.add_argument("--t-end", type=float, default=value["t_end"],
                          help=f"end time of every orbit (default {shown(value['t_end'])})")
    poincare.add_argument("--tau0", type=float, default=None,
                          help="first step (default: the scene's)")
    poincare.add_argument("--seed", type=int, default=value["seed"],
                          help=f"seed of the starts (default {value['seed']})")
    poincare.add_argument("--set", dest="settings", action="append", default=[],
                          metavar="NAME=VALUE", help="a parameter of the scene")
    poincare.add_argument("--out", default=None,
                          help="output folder (default: runs/SCENE-poincare-EENERGY; -HASH of "
                               "the other settings when they are not the defaults)")
    poincare.add_argument("--no-plot", action="store_true", help="do not write the figure")
    _progress_arguments(poincare, "the blocks of orbits done, on a Dask cluster; the local "
                                  "workers report none")
    poincare.add_argument("--workers", type=int, default=value["workers"],
                          help=f"local worker processes marching the orbits (default: "
                               f"{value['workers']})")
    poincare.add_argument("--scheduler", default=None, metavar="ADDRESS",
                          help="march the orbits on this Dask scheduler, e.g. tcp://host:8786 "
                               "(default: $DDVP_SCHEDULER, else local workers)")
    _cluster_argument(poincare)
    _accuracy_arguments(poincare)


def _chaos_command(chaos: argparse.ArgumentParser) -> None:
    chaos.add_argument("scene", nargs="?", default=None,
                       help="a built-in scene name (see `ddvp scenes`) or a .py file, of two "
                            "degrees of freedom")
    chaos.add_argument("--energy", type=float, default=None, help="the energy E (required)")
    value = {name: api_default("chaos", name) for name in ("section", "t_end", "workers")}
    chaos.add_argument("--section", default=value["section"], metavar="NAME=VALUE",
                       help=f"the section the cells start on, q1 or q2 (default "
                            f"{value['section']}); the conjugate momentum is the positive "
                            "root of H = E")
    chaos.add_argument("--grid", default=None, metavar="q2=A:B:N,p2=C:D:M",
                       help="the cells: N values of the other coordinate from A to B and M of "
                            "its momentum from C to D (required)")
    chaos.add_argument("--t-end", type=float, default=value["t_end"],
                       help=f"end time of every cell (default {shown(value['t_end'])}); the "
                            "indicators are also kept at t-end/2")
    chaos.add_argument("--tau0", type=float, default=None,
                       help="first step, which sets the discrete energy level (default: the "
                            "scene's)")
    chaos.add_argument("--set", dest="settings", action="append", default=[],
                       metavar="NAME=VALUE", help="a parameter of the scene")
    chaos.add_argument("--out", default=None,
                       help="output folder (default: runs/SCENE-chaos-EENERGY; -HASH of the "
                            "other settings when they are not the defaults)")
    chaos.add_argument("--shard", default=None, metavar="K/N",
                       help="run only the K-th of N parts of the cells, into OUT/shard-K-of-N/ "
                            "(a SLURM array task); join them with --merge OUT")
    chaos.add_argument("--merge", default=None, metavar="DIR",
                       help="join the parts of DIR/shard-*-of-N/ into DIR/chaos.npz and "
                            "chaos.png (no other option)")
    chaos.add_argument("--fresh", action="store_true",
                       help="ignore the journal of an earlier run of the same map (default: "
                            "go on from its finished blocks)")
    chaos.add_argument("--no-plot", action="store_true", help="do not write the figure")
    _progress_arguments(chaos, "the blocks of cells done")
    chaos.add_argument("--workers", type=int, default=value["workers"],
                       help=f"local worker processes (default: {value['workers']}; 1: in this "
                            "process)")
    chaos.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run the cells on this Dask scheduler, e.g. tcp://host:8786 "
                            "(default: $DDVP_SCHEDULER, else local workers)")
    _cluster_argument(chaos)


def _periodic_command(periodic: argparse.ArgumentParser) -> None:
    periodic.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    periodic.add_argument("--energy", type=float, default=None,
                          help="the prescribed energy E (default: the scene's)")
    periodic.add_argument("--nodes", type=int, default=None,
                          help="number of nodes of the closed grid, the last equal to the first "
                               f"(default: the scene's, else {periodic_nodes()})")
    periodic.add_argument("--section", default=None, metavar="NAME=VALUE",
                          help="phase condition on node 0, NAME in q1..qn, p1..pn "
                               "(default: the scene's, else p1=0)")
    periodic.add_argument("--family", default=None, metavar="E1:E2:COUNT",
                          help="continue the orbit over COUNT energies from E1 to E2")
    periodic.add_argument("--scheme", default=api_default("periodic", "scheme"),
                          choices=("vddvp", "lee"),
                          help="energy rule (the same equations for autonomous H)")
    solver = api_default("periodic", "solver")
    periodic.add_argument("--solver", default=solver, metavar="newton|ipopt|auto",
                          help="Newton with sparse LU, IPOPT, or Newton then IPOPT when "
                               f"Newton's orbit fails its verification (default: {solver})")
    periodic.add_argument("--guess", default=None, metavar="FILE",
                          help="start from a run folder / result.npz (t, q, p over one period)")
    periodic.add_argument("--set", dest="settings", action="append", default=[],
                          metavar="NAME=VALUE", help="a parameter of the scene")
    periodic.add_argument("--out", default=None,
                          help="output folder (default: runs/SCENE-periodic, or "
                               "runs/SCENE-family-HASH; -HASH of the energy and every other "
                               "setting when they are not the scene's defaults)")
    periodic.add_argument("--no-plot", action="store_true", help="do not write the figures")
    _progress_arguments(periodic, "none yet: the periodic solvers report no progress; "
                                  "accepted like on every command")
    _accuracy_arguments(periodic)
    periodic.add_argument("--stability", action="store_true",
                          help="the Floquet multipliers, stability indices and verdict of the "
                               "orbit (of each orbit of --family), checked against the exact "
                               "flow (stability.json)")
    marginal = api_default("periodic", "stability_tol")
    periodic.add_argument("--stability-tol", type=float, default=marginal, metavar="TOL",
                          help=f"a stability index within TOL of +-2 is marginal (default "
                               f"{shown(marginal)})")
    periodic.add_argument("--follow", type=float, default=None, metavar="E_END",
                          help="follow the family from --energy towards E_END by "
                               "pseudo-arclength continuation (through folds), every orbit's "
                               "stability, the bifurcations located and confirmed on the exact "
                               "flow")
    periodic.add_argument("--step", type=float, default=None, metavar="DE",
                          help="with --follow: the first step in the energy (default: a "
                               "twentieth of the range)")
    most = api_default("periodic", "max_orbits")
    periodic.add_argument("--max-orbits", type=int, default=most,
                          help=f"with --follow: at most this many orbits (default {most})")
    _switch_options(periodic)
    periodic.add_argument("--search", action="store_true",
                          help="search the section (--section q1=V or q2=V) at --energy for "
                               "periodic orbits from seeds over the region the energy allows "
                               "(two degrees of freedom): orbits.csv, orbits.png")
    value = {name: api_default("periodic", name) for name in ("seeds", "max_returns",
                                                               "reversing", "workers")}
    periodic.add_argument("--seeds", type=int, default=None,
                          help="with --search: N seeds on the symmetric line (both crossing "
                               "directions), and N on a grid of the whole map (about N of its "
                               "points accessible, more in all); --reversing auto searches both "
                               "where H has the symmetry, about 2N seeds or more; the header "
                               f"counts each (default {value['seeds']})")
    periodic.add_argument("--max-returns", type=int, default=None,
                          help="with --search: orbits of up to this many upward crossings "
                               "of the section per period (the 'returns' listed); a shot that "
                               "closes on an orbit of more is listed among the failed seeds "
                               f"(default {value['max_returns']})")
    periodic.add_argument("--reversing", default=None, metavar="NAMES|auto|none",
                          help="with --search: the coordinates a reversing symmetry flips, "
                               "e.g. q2,p1 for the section q2=0: half-orbit shots (default "
                               f"{value['reversing']}: that symmetry where H is unchanged by "
                               "it; none: the whole return map)")
    periodic.add_argument("--jitter", type=int, default=None, metavar="SEED",
                          help="with --search: each seed at a random point of its cell "
                               "(numpy's generator seeded SEED, an integer >= 0) instead of its "
                               "centre, to see whether the orbits found depend on the layout")
    periodic.add_argument("--workers", type=int, default=None,
                          help="with --search: local processes the seeds' returns and shots "
                               f"run on (default {value['workers']}: in this process)")


def _switch_options(periodic: argparse.ArgumentParser) -> None:
    """``ddvp periodic``'s branch switching: ``--switch`` and its error target."""
    periodic.add_argument("--switch", type=int, nargs="?", const=20, default=None,
                          metavar="ORBITS",
                          help="with --follow: at the first branch point or period doubling "
                               "located, switch onto the new branch (its direction from the "
                               "kernel of the extended system) and follow both its halves for "
                               "ORBITS orbits each (default 20), every orbit verified on the "
                               "exact flow (branch-1/, branch-2/); at a period doubling the two "
                               "halves are one orbit of twice the period, followed once")
    switch_tol = api_default("periodic", "switch_tol")
    periodic.add_argument("--switch-tol", default=None, metavar="TOL",
                          help="with --switch: at a branch point, the halves' periods' error "
                               "target relative to the period (each half followed on a grid "
                               f"chosen for it, every orbit's error estimated; default "
                               f"{switch_tol:g}); 'none': on the family's grid, unchecked")


def _march_command(march: argparse.ArgumentParser) -> None:
    _scheme_arguments(march, "march", COMPARED_METHODS, scene_optional=True)
    march.add_argument("--resume", default=None, metavar="FOLDER",
                       help="continue the march in FOLDER (a killed run's last checkpoint or a "
                            "finished run) with the options it ran with, to its t_end or "
                            "--t-end; the nodes equal an uninterrupted run's bit for bit")
    march.add_argument("--t-end", type=float, default=None,
                       help="the end time (the same as --set t_end=T); with --resume: "
                            "continue to this later end time")
    march.add_argument("--target-error", type=float, default=api_default("march", "target_error"),
                       metavar="E",
                       help="ask for a trajectory error instead of a step: the march chooses its "
                            "tau0 from a pilot march at the scene's tau0, so that the run is "
                            "accurate at E of the motion's size (a second try where it is not); "
                            "the printout and meta.json give the tau0 chosen and its cost")
    march.add_argument("--t-eval", default=None, metavar="T1,T2,...|START:STOP:COUNT",
                       help="also report the state (q, p) at these times, from the scheme's "
                            "dense output (result.npz: t_eval, z_eval)")
    march.add_argument("--event", dest="events", action="append", default=[],
                       metavar="EXPR[;up|down][;terminal[=N]]",
                       help="an event: where EXPR, an expression in t, q1.., p1.. and the "
                            "scene's parameters (e.g. 'q1 - 0.5', 'p1*q2 - q1*p2'), is zero, "
                            "located to round-off on the dense output; up/down: one direction "
                            "of crossing only; terminal: end the march there (at the N-th); "
                            "repeatable (result.npz: t_events_K, z_events_K; meta.json)")
    value = {name: api_default("march", name) for name in
             ("max_steps", "tau_min", "tau_max", "max_step_ratio", "time_limit",
              "energy_guard", "checkpoint_every")}
    march.add_argument("--max-steps", type=int, default=value["max_steps"],
                       help=f"stop after this many steps (status max_steps; default: "
                            f"{value['max_steps']})")
    march.add_argument("--tau-min", type=float, default=value["tau_min"],
                       help=f"smallest accepted step (default: {shown(value['tau_min'])})")
    march.add_argument("--tau-max", type=float, default=value["tau_max"],
                       help=f"largest accepted step (default: {shown(value['tau_max'])})")
    march.add_argument("--max-step-ratio", type=float, default=value["max_step_ratio"],
                       help="largest accepted ratio between consecutive steps (default: "
                            f"{shown(value['max_step_ratio'])})")
    march.add_argument("--time-limit", type=float, default=value["time_limit"],
                       help="stop after this many seconds of stepping, wall time (status "
                            f"time_limit; default: {shown(value['time_limit'])})")
    march.add_argument("--energy-guard", type=float, default=value["energy_guard"],
                       help="stop when |H - H0| / max(|H0|, E) exceeds this at a node, E "
                            "how much H changes when the start moves by its own size "
                            f"(default: {shown(value['energy_guard'])})")
    march.add_argument("--least-squares", action="store_true",
                       help="where the energy step has no admissible root, take the least-squares "
                            "step (Kane-Marsden-Ortiz) within [tau-min, tau-max] and go on; each "
                            "such step is flagged in meta.json and result.npz")
    _accuracy_arguments(march)
    march.add_argument("--careful", action="store_true",
                       help="force the careful per-step path (default: compiled chunks of steps, "
                            "checked step by step by the same test; their nodes differ by "
                            "round-off)")
    march.add_argument("--checkpoint-every", type=float, default=value["checkpoint_every"],
                       metavar="SECONDS",
                       help="write the run so far to the output folder this often while "
                            f"marching, so a kill loses at most this much (default: "
                            f"{shown(value['checkpoint_every'])})")
    march.add_argument("--keep-every", type=int, default=None, metavar="K",
                       help="keep only every K-th node (and the last) of a long march: memory "
                            "and result.npz grow with the nodes kept; every node is still "
                            "checked and judged as the march goes; no checkpoints, no --resume "
                            "(default: every node)")
    march.add_argument("--keep", choices=("nodes", "t_eval"), default=api_default("march", "keep"),
                       help="t_eval: keep only the --t-eval states and the --event crossings "
                            "(and the first and last node), judged as with --keep-every "
                            "(default: nodes)")
    _progress_arguments(march, "the time reached; default on")
    _figure_arguments(march, "trajectory.png")


def _figure_arguments(parser: argparse.ArgumentParser, figure: str, plot: bool = True) -> None:
    """``--format`` of the figures (``io/figures.py``) and, if ``plot``, ``--no-plot``."""
    from ..io.figures import FORMATS

    if plot:
        parser.add_argument("--no-plot", action="store_true", help=f"do not write {figure}")
    parser.add_argument("--format", dest="figure_format", default=FORMATS[0], choices=FORMATS,
                        help=f"file format of {figure} (default: {FORMATS[0]}; svg and pdf are "
                             "vector graphics)")


def _accuracy_arguments(parser: argparse.ArgumentParser) -> None:
    """The accuracy check (``solvers/accuracy/judgement.py``): a verdict that does not trust
    the scheme."""
    group = parser.add_argument_group(
        "accuracy check", "the run against the exact flow z' = (H_p, -H_q), every figure "
        "relative to the motion's own size S (each component's range over the run) and energy "
        "scale E_s; the verdict is accurate, drifted (each step follows the flow, the energy is "
        "right, the trajectory error passes --global-tol from t_drift on: exit 0 unless "
        "--require-accurate) or inaccurate (exit 1)")
    value = {name: api_default("accuracy", name)
             for name in ("rtol", "atol", "energy_tol", "global_tol")}
    group.add_argument("--rtol", type=float, default=value["rtol"],
                       help="local error test of every step: |d_k,i| <= rtol S_i "
                            f"(default: {shown(value['rtol'])})")
    group.add_argument("--atol", type=float, default=value["atol"],
                       help="an absolute allowance added to the local bound, in the units of "
                            f"z (default: {shown(value['atol'])})")
    group.add_argument("--energy-tol", type=float, default=value["energy_tol"],
                       help="bound on the first step's energy level error and the nodal energy "
                            f"drift, relative to E_s (default: {shown(value['energy_tol'])})")
    group.add_argument("--global-tol", type=float, default=value["global_tol"],
                       help="the trajectory tolerance: max_i |z_i - z_ref,i| / S_i at every "
                            f"node (default: {shown(value['global_tol'])})")
    group.add_argument("--require-accurate", action="store_true",
                       help="a drifted run fails (status drifted, exit 1)")
    group.add_argument("--accept-inaccurate", action="store_true",
                       help="an inaccurate run keeps its status (the verdict is recorded)")


def _bvp_command(bvp: argparse.ArgumentParser) -> None:
    _scheme_arguments(bvp, "bvp")
    bvp.add_argument("--nodes", type=int, default=None,
                     help=f"number of nodes (default: the scene's, else {BOUNDARY_NODES})")
    solver = api_default("bvp", "solver")
    bvp.add_argument("--solver", default=solver, metavar="auto|newton|ipopt",
                     help="auto (banded Newton, then IPOPT if its point fails the "
                          f"verification), newton or ipopt (default: {solver})")
    bvp.add_argument("--guess", default="straight", metavar="straight|march|FILE",
                     help="start: straight line (default), march (shooting from q_start), or "
                          "a run folder / result.npz (its t, q, p resampled onto --nodes "
                          "rows if it has another number)")
    bvp.add_argument("--p-start", default=None, metavar="P1,P2,...",
                     help="with --guess march: the momentum shooting starts from (default the "
                          "straight line's); picks the branch of a problem with several "
                          "solutions")
    bvp.add_argument("--energy", type=float, default=None,
                     help="a transfer at this energy E: the end time becomes an unknown (the "
                          "scene's t_end - t0 its guess), every interval's energy is E")
    bvp.add_argument("--time-limit", type=float, default=api_default("bvp", "time_limit"),
                     help="stop after this many seconds, wall time (status time_limit)")
    _progress_arguments(bvp, "a line per solver iteration; default on a terminal from "
                             "100000 nodes")
    bvp.add_argument("--verbose", action="store_true", help="show IPOPT's output")
    _figure_arguments(bvp, "trajectory.png")
    _accuracy_arguments(bvp)


def _compare_command(compare: argparse.ArgumentParser) -> None:
    from ..studies.methods import METHODS

    compare.add_argument("scene", help="a built-in scene name (see `ddvp scenes`) or a .py file")
    compare.add_argument("--methods", default=None,
                         help="comma-separated methods (default: every one that applies); "
                              f"known: {', '.join(METHODS)}")
    compare.add_argument("--set", dest="settings", action="append", default=[],
                         metavar="NAME=VALUE",
                         help="override a scene parameter or t0, tau0, t_end, q0, p0; repeatable")
    compare.add_argument("--out", default=None,
                         help="output folder (default: runs/SCENE-compare; -HASH of the "
                              "settings, methods and sweeps when they are not the defaults)")
    value = {name: api_default("compare", name) for name in
             ("halvings", "repeats", "time_unit", "max_steps", "run_budget", "reference_span")}
    compare.add_argument("--halvings", type=int, default=value["halvings"],
                         help="step sweeps go from 2 tau0 down by this many halvings "
                              f"(default: {value['halvings']})")
    compare.add_argument("--repeats", type=int, default=value["repeats"],
                         help="timed calls per run after one warm-up; best is kept (default: "
                              f"{value['repeats']})")
    compare.add_argument("--target-errors", default=None, metavar="E1,E2,...",
                         help="run the march's schemes once per trajectory error asked for "
                              "(march --target-error), instead of their step sweeps; the "
                              "other methods keep their sweeps")
    compare.add_argument("--no-compile", action="store_true",
                         help="run the compiled methods on CasADi's virtual machine instead")
    _progress_arguments(compare, "the runs done; default on")
    compare.add_argument("--horizons", default=None, metavar="T1,T2,...",
                         help="compare at each horizon t_end = t0 + T * --time-unit (e.g. "
                              "10,1000,100000): horizons.png, growth.png, horizons.md and a "
                              "report per horizon")
    compare.add_argument("--time-unit", type=float, default=value["time_unit"],
                         help="unit of --horizons, e.g. 6.283185307 for Kepler's period "
                              f"(default: {shown(value['time_unit'])}, the scene's time unit)")
    compare.add_argument("--max-steps", type=int, default=value["max_steps"],
                         help="bound on the steps of each run; with --horizons runs needing "
                              f"more give way to coarser steps (default: {value['max_steps']})")
    compare.add_argument("--run-budget", type=float, default=value["run_budget"],
                         metavar="SECONDS",
                         help="with --horizons: runs predicted from the shorter horizon to "
                              f"take longer are left out (default: {shown(value['run_budget'])})")
    compare.add_argument("--reference-span", type=float, default=value["reference_span"],
                         metavar="T",
                         help="with --horizons, scenes without an exact solution: beyond this "
                              "span of time the DOP853 reference is not computed and only the "
                              f"energy error is measured (default: "
                              f"{shown(value['reference_span'])})")
    _grid_arguments(compare, "1: the run times are what is compared")


def _stress_command(stress: argparse.ArgumentParser) -> None:
    stress.add_argument("--out", default=None,
                        help="output folder (default: runs/stress; -HASH of the bounds and "
                             "--quick when they are not the defaults)")
    stress.add_argument("--quick", action="store_true",
                        help="a few cases on short horizons (seconds)")
    _run_bounds(stress, defaults=True)
    stress.add_argument("--resume", action="store_true",
                        help="keep the rows already in OUT/stress.csv; run only the missing ones")
    _grid_arguments(stress, "one per core")


def _sweep_command(sweep: argparse.ArgumentParser) -> None:
    from ..studies.stress import DEFAULT_METHODS

    sweep.add_argument("scene", nargs="?", default=None,
                       help="a built-in scene name or a .py file (or give --file)")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=SPEC",
                       help="an axis: NAME=FROM:TO:COUNT or NAME=V1,V2,...; NAME is a scene "
                            "parameter, t_end, t0, tau0 (the step) or rtol (DOP853); repeatable")
    sweep.add_argument("--file", default=None, help="a TOML grid file (see `ddvp_nlp.sweep`)")
    sweep.add_argument("--allow-scene", default=None, metavar="FILE",
                       help="the scene file a --file grid names, allowed to run (a grid file "
                            "runs no code the command line does not name: its scene is a "
                            "built-in name, or this file)")
    sweep.add_argument("--methods", default=None,
                       help=f"comma-separated methods (default: {', '.join(DEFAULT_METHODS)} "
                            "where they apply)")
    sweep.add_argument("--set", dest="settings", action="append", default=[],
                       metavar="NAME=VALUE", help="a fixed scene parameter or setting")
    sweep.add_argument("--out", default=None,
                       help="output folder (default: runs/SCENE-sweep-HASH, HASH of the grid, "
                            "methods, settings and bounds: another grid never shares it)")
    sweep.add_argument("--fresh", action="store_true",
                       help="start afresh instead of resuming from OUT/sweep.csv")
    _run_bounds(sweep, defaults=False)
    _grid_arguments(sweep, "one per core")


def _reproduce_command(reproduce: argparse.ArgumentParser) -> None:
    reproduce.add_argument("--out", default=None,
                           help="output folder (default: runs/reproduce, with -HASH for "
                                "--quick)")
    reproduce.add_argument("--quick", action="store_true",
                           help="shorter runs and fewer step sizes (about 10 s)")
    _grid_arguments(reproduce, "1")
    _progress_arguments(reproduce, "none yet: its runs report no progress; accepted like on "
                                   "every command")
