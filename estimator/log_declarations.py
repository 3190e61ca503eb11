"""The declarations a user puts beside a log (``LOG.timing.toml``, ``LOG.noise.toml``), read
through their schemas (userio.schema.logs) into the estimator's own types. Kept apart from
estimator.timing and estimator.noise, which the schemas import for their ranges and grammar."""

from __future__ import annotations

import numpy as np

from estimator import noise, timing


def read_side_table(log_path, names):
    """(path, {key: (kind, delay_s)}) of a log's ``LOG.timing.toml`` validated by its schema
    (userio.schema.logs.TimingFile: keys default, wrench, tau or one of ``names``, the log's
    channels); None when the log has none."""
    from userio.files import read_toml
    from userio.schema import parse
    from userio.schema.logs import TimingFile

    path = timing.side_file(log_path)
    if not path.exists():
        return None
    file = parse(TimingFile, read_toml(path), path, {"channels": list(names)})
    return path, file.timing


def read_declaration(log_path, n_links: int):
    """Per-channel [(kind, delay_s)] from the side file, or None when there is none."""
    names = timing.channel_names(n_links)
    found = read_side_table(log_path, names)
    if found is None:
        return None
    _, table = found
    default = table.get("default", ("instant", 0.0))
    out = []
    for j, name in enumerate(names):
        group = "wrench" if j < 3 else "tau"
        key = name if name in table else group if group in table else None
        out.append(table[key] if key else default)
    return out


def read_noise_declaration(log_path, n_links: int) -> noise.NoiseModel | None:
    """The NoiseModel declared in ``LOG.noise.toml`` beside the log (userio.schema.logs.NoiseFile:
    torque_sigma_Nm one value or one per link, ft_sigma three), or None without one."""
    from userio.files import read_toml
    from userio.schema import parse
    from userio.schema.logs import NoiseFile

    path = noise.noise_side_file(log_path)
    if not path.exists():
        return None
    t = parse(NoiseFile, read_toml(path), path, {"torque_sizes": (1, n_links), "ft_sizes": (3,), "planar": True}).noise
    return noise.NoiseModel(torque_sigma_Nm=np.asarray(t.torque_sigma_Nm, float),
                            ft_sigma=np.asarray(t.ft_sigma, float),
                            velocity_sigma_rad_per_s=t.velocity_sigma_rad_per_s,
                            encoder_counts=t.encoder_counts, source=f"log declaration {path.name}")
