"""The one schema layer of every input file: one pydantic model per file kind.

    from userio.schema import parse
    model = parse(RobotFile, read_toml(path), path)      # InputError "FILE: link[2].mass_kg: ..."

Loaders import the models inside their functions (pydantic costs ~90 ms to import; light commands
never pay it). ``userio.schema.base``: the model base, field helpers and the one error formatter;
one module per file kind; ``python -m userio.schema.docs`` writes docs/inputs.md from the models.
"""

from __future__ import annotations


def parse(model, data, source, context: dict | None = None):
    """``data`` validated as ``model`` (a userio.schema model class); InputError naming
    ``source`` and the field on failure."""
    from userio.schema.base import parse as _parse

    return _parse(model, data, source, context)
