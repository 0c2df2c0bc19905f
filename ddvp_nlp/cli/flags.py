"""Which command-line flag stands for which field: the one table the command line reads to say
a refused value in its own words. The option objects (`StepControl`, `Tolerance`, `Output`,
`GridOptions`, `Continuation`, `Scheme`, the studies' options) and the studies check their
values and name the field (``tau_min must be < tau_max = 0.01, got 0.1``); the command line
says the same with the flags (``--tau-min must be < --tau-max = 0.01, got 0.1``). A field is
named where the message starts with it, where it is compared with (``< tau_max =``) and where
a message quotes it in backquotes (```shard``` K/N)."""

from __future__ import annotations

import contextlib
import re

from ..errors import InputError

# field -> flag. The fields of the option objects by name; a field whose flag depends on the
# object or the function it belongs to is written ``owner.field`` (the continuation's ``tol``
# is the stability verdicts', ``--stability-tol``; a chaos map's ``grid`` is ``--grid``, a
# grid file's is not), and read only where the command line says whose fields a message
# names (`flags`).
FLAGS = {
    # StepControl (march, stress, sweep), GridOptions (bvp, periodic)
    "tol": "--tol", "tau_min": "--tau-min", "tau_max": "--tau-max",
    "max_step_ratio": "--max-step-ratio", "max_steps": "--max-steps",
    "time_limit": "--time-limit", "energy_guard": "--energy-guard",
    # Tolerance (march, bvp, periodic, poincare)
    "rtol": "--rtol", "atol": "--atol", "energy_tol": "--energy-tol",
    "global_tol": "--global-tol",
    # Output (march)
    "checkpoint_interval": "--checkpoint-every", "keep_every": "--keep-every",
    # Scheme (march, bvp)
    "alpha": "--alpha",
    # CompareOptions (compare)
    "halvings": "--halvings", "repeats": "--repeats", "target_errors": "--target-errors",
    # Continuation (periodic)
    "Continuation.tol": "--stability-tol", "Continuation.step": "--step",
    "Continuation.max_orbits": "--max-orbits",
    # Workers (the commands that run many tasks)
    "workers": "--workers",
    # the chaos map and its shards (studies/chaos_map.py)
    "chaos_map.energy": "--energy", "chaos_map.grid": "--grid",
    "chaos_map.section": "--section", "chaos_map.shard": "--shard",
    "chaos_map.t_end": "--t-end", "merge_shards.folder": "--merge",
    "merge_shards.shard": "--shard", "merge_shards.out": "--out",
    # a sweep's axes and grid file (studies/sweep.py, studies/sweep_file.py)
    "parse_axis.grid": "--grid", "load_grid_file.allowed": "--allow-scene",
    # a comparison's scene settings (studies/comparable.py)
    "comparison.settings": "--set",
}

_LEADING = re.compile(r"[a-z_][a-z0-9_]*(?=[ :])")
_COMPARED = re.compile(r"(?<=< )[a-z_][a-z0-9_]*(?= = )")
_QUOTED = re.compile(r"`([a-z_][a-z0-9_]*)`")


def flag(field: str, owner: str | None = None) -> str | None:
    """The flag of ``field`` of an option object, or of the object or function ``owner``, if
    the command line has one."""
    return FLAGS.get(field if owner is None else f"{owner}.{field}")


def in_flags(text: str, owner: str | None = None) -> str:
    """A message that names fields, in the command line's words."""
    def named(match: re.Match, group: int = 0) -> str:
        return flag(match.group(group), owner) or match.group(0)

    text = _LEADING.sub(named, text, count=1) if _LEADING.match(text) else text
    text = _COMPARED.sub(named, text)
    return _QUOTED.sub(lambda match: named(match, 1), text)


@contextlib.contextmanager
def flags(owner: str | None = None):
    """An `InputError` raised inside, said with the flags (its fields those of ``owner``)."""
    try:
        yield
    except InputError as error:
        raise InputError(in_flags(str(error), owner)) from None
