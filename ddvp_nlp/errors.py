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

    @classmethod
    def because(cls, error: "OutputError", note: str) -> "OutputError":
        """``error`` with ``note`` (what the folder holds now) added to its message."""
        found = cls(error.path, OSError(error.errno, "see below"))
        found.args = (error.errno, f"{error}; {note}")
        return found

__all__ = ["InputError", "OutputError"]
