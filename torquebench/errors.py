"""The user errors the CLI turns into exit code 2 and one line on stderr."""

from userio.errors import InputError

USER_ERRORS = (
    InputError,
    FileNotFoundError,
    IsADirectoryError,
    NotADirectoryError,
    PermissionError,
)

__all__ = ["InputError", "USER_ERRORS"]
