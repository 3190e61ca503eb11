"""Errors a user can fix: the project's one `InputError` (``userio.errors``), re-exported here."""

from userio.errors import InputError

__all__ = ["InputError"]
