"""The run folder of a command: its default name and what it holds after an interrupt."""

from __future__ import annotations


def holds(out) -> str:
    from ..io.atomic import describe

    return describe(out.path)


def default_or(args, label: str, named: dict, defaults: dict):
    """``(folder, owned)``: ``--out``, else ``runs/LABEL`` for the defaults and
    ``runs/LABEL-HASH`` (``HASH`` of every setting) when any setting differs from them."""
    from ..io.run_folder import default_folder

    if args.out is not None:
        return args.out, 1
    changed = {k: v for k, v in named.items() if defaults.get(k, object()) != v}
    return default_folder(label, named, changed), 2
