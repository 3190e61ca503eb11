"""Report builders: one module per area, each with ``build(out_dir: Path) -> list[Path]`` writing
``<out_dir>/<area>.md`` (+ PNGs). ``torquebench report`` discovers and runs them all."""
