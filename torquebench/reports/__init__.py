"""Report builders: one module per area, each with ``build(out_dir: Path) -> list[Path]`` writing
``<out_dir>/<area>.md`` (+ PNGs). ``torquebench report`` discovers and runs them all."""


def load_1min() -> float | None:
    """The machine's 1-minute load average, rounded to 0.1 (None where the system does not say): a
    build time or a report's wall times mean little without it."""
    import os

    try:
        return round(os.getloadavg()[0], 1)
    except (OSError, AttributeError):
        return None
