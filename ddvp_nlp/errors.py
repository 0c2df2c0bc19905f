"""The one exception the library raises for bad input."""


class InputError(ValueError):
    """Bad input, found before any solver is built. The message names the argument and value."""


class OutputError(OSError):
    """A file of the output could not be written (a full disk, a read-only folder, ...). The
    message names the path; the command ends with exit code 1, never a traceback."""

    def __init__(self, path, cause: OSError):
        self.path = str(path)
        reason = cause.strerror or str(cause)
        super().__init__(cause.errno, f"cannot write {self.path}: {reason}")

    def __str__(self) -> str:
        return self.args[1]
