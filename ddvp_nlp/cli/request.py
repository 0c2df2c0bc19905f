"""One command line as a frozen request: its options as parsed and its command's defaults, read
once from the parser that parsed it (no second parser is built to learn a default). A command
reads the request and never assigns to it; what it works out from the request (the scheme a
scene declares, the checked output times, a cluster's scheduler) is a new request made with
`Request.but`, the one it was given left as it is.

A function shared by several commands reads an option some of them do not have (``ddvp bvp``
has no ``--t-eval``, ``ddvp periodic`` no ``--tol``): what such an option reads as on a command
without it is declared once, in `ABSENT`, not guessed at each reading."""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Iterable, Mapping
from types import MappingProxyType


def _grid_default(name: str):
    from ..solvers import GridOptions

    return {f.name: f.default for f in dataclasses.fields(GridOptions)}[name]


# What an option reads as on a command that does not have it, by name (a function: the value
# is read where it is asked for, as the API's defaults are).
ABSENT = {
    # the grid solve of `ddvp periodic` (no --tol, --time-limit, --verbose): GridOptions' own
    "tol": lambda: _grid_default("tol"),
    "time_limit": lambda: _grid_default("time_limit"),
    "verbose": lambda: _grid_default("verbose"),
    # what `ddvp bvp` lacks of a march's run (cli/one_run.py)
    "t_end": lambda: None, "t_eval": lambda: None, "events": lambda: (),
    "method": lambda: None,
    # worked out by `ddvp bvp` from a guess file (cli/one_run.py)
    "guess_data": lambda: None,
    # the commands that start no cluster and take no method list, section or horizons
    "cluster": lambda: None, "methods": lambda: None, "section": lambda: None,
    "horizons": lambda: None,
}


@dataclasses.dataclass(frozen=True)
class Request:
    """``command``; ``options``: every option of the command by its name (``dest``), as given
    or defaulted; ``defaults``: each option's default (the API's, ``arguments.API_DEFAULTS``,
    or the command line's own). An option reads as an attribute: ``request.tol``; one the
    command does not have reads as `ABSENT` declares, or is an ``AttributeError``."""

    command: str
    options: Mapping[str, object]
    defaults: Mapping[str, object]

    @classmethod
    def read(cls, args: argparse.Namespace, parser: argparse.ArgumentParser) -> Request:
        """The request of ``args`` as ``parser`` (the command's own parser) parsed them."""
        options = {name: value for name, value in vars(args).items() if name != "command"}
        defaults = {name: parser.get_default(name) for name in options}
        return cls(args.command, MappingProxyType(options), MappingProxyType(defaults))

    def __getattr__(self, name: str):
        options = self.__dict__.get("options", {})
        if name in options:
            return options[name]
        if name in ABSENT:
            return ABSENT[name]()
        raise AttributeError(f"ddvp {self.__dict__.get('command')} has no option {name!r}")

    def default(self, name: str):
        """The default of option ``name`` (`ABSENT`'s value for one the command lacks)."""
        if name not in self.defaults and name in ABSENT:
            return ABSENT[name]()
        return self.defaults[name]

    def having(self, names: Iterable[str]) -> dict:
        """The options among ``names`` that the command has, by name."""
        return {name: self.options[name] for name in names if name in self.options}

    def changed(self, names: Iterable[str]) -> dict:
        """The options among ``names`` that the command has and that differ from their
        default."""
        return {name: value for name, value in self.having(names).items()
                if value != self.defaults.get(name)}

    def but(self, **changes) -> Request:
        """This request with ``changes`` (names it works out, or options it resolves)."""
        return dataclasses.replace(self, options=MappingProxyType({**self.options, **changes}))
