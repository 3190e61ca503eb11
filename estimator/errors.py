"""Errors a user can fix: bad files, bad parameters.

The CLI turns an `InputError` into exit code 2 and its message on one line of stderr, so the
message must name the file, line, column or field and say what is wrong.
"""


class InputError(ValueError):
    """Bad user input (file, parameter); the message names where and what."""
