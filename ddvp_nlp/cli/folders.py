"""The run folder of a command: its default name (named by every setting that changes the
result, each compared with its default, the parser's, which is the API's), and what it holds
after an interrupt."""

from __future__ import annotations

import functools

from ..io.atomic import describe
from ..io.run_folder import default_folder
from .parser import build_parser


def holds(out) -> str:
    """What the output folder ``out`` holds, in words (said when a command stops early)."""
    return describe(out.path)


@functools.cache
def _command_parser(command: str):
    return build_parser(command).commands[command]


def command_default(command: str, name: str):
    """The default of option ``name`` of ``command``: the parser's, which is the API's
    (``arguments.API_DEFAULTS``)."""
    return _command_parser(command).get_default(name)


def default_or(args, label: str, named: dict, *, options=(), defaults: dict | None = None):
    """``(folder, owned)``: ``--out``, else ``runs/LABEL`` for the defaults and
    ``runs/LABEL-HASH`` (``HASH`` of every setting in ``named``) when any setting differs from
    its default: the command's own for the names in ``options``, else ``defaults``."""
    if args.out is not None:
        return args.out, 1
    reference = {name: command_default(args.command, name) for name in options}
    reference.update(defaults or {})
    changed = {k: v for k, v in named.items() if reference.get(k, object()) != v}
    return default_folder(label, named, changed), 2
