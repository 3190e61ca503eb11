"""Subcommands of the ``torquebench`` CLI, one module each (see ``torquebench.cli``)."""
