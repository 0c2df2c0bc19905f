"""One command line as a frozen request: its options as parsed and its command's defaults, read
once from the parser that parsed it (no second parser is built to learn a default). A command
reads the request and never assigns to it; what it works out from the request (the scheme a
scene declares, the checked output times, a cluster's scheduler) is a new request made with
`Request.but`, the one it was given left as it is."""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Mapping
from types import MappingProxyType


@dataclasses.dataclass(frozen=True)
class Request:
    """``command``; ``options``: every option of the command by its name (``dest``), as given
    or defaulted; ``defaults``: each option's default (the API's, ``arguments.API_DEFAULTS``,
    or the command line's own). An option reads as an attribute: ``request.tol``."""

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
        raise AttributeError(f"ddvp {self.__dict__.get('command')} has no option {name!r}")

    def default(self, name: str):
        """The default of option ``name``."""
        return self.defaults[name]

    def but(self, **changes) -> Request:
        """This request with ``changes`` (names it works out, or options it resolves)."""
        return dataclasses.replace(self, options=MappingProxyType({**self.options, **changes}))
