"""The one exception the library raises for bad input."""


class InputError(ValueError):
    """Bad input, found before any solver is built. The message names the argument and value."""
