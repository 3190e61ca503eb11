"""How each force channel of a log was sampled, and the matching step mean for the observer.

Channels are the measured generalized force [Fx, Fz, My, τ_1…τ_N] (estimator.log). Each one is

* ``instant``  — the value at the sample time t_k (the default);
* ``mean``     — the mean over the interval (t_{k−1}, t_k] that ENDS at t_k (an integrating ADC,
  e.g. a delta-sigma converter's sinc filter, reporting once per sample);
* ``delay:D``  — a filtered reading with group delay D seconds: reading(t_k) ≈ τ(t_k − D).

The observer needs the mean of τ over each step [t_k, t_{k+1}] (observer.residual_offline):

    instant:  τ̄_k = (τ_k + τ_{k+1}) / 2                  (trapezoid)
    mean:     τ̄_k = reading_{k+1}                          (exact for any τ(t))
    delay D:  τ(t_k) = reading(t_k + D) (linear interpolation, s = D/Δt samples ahead, last
              value held past the end), then the trapezoid.

Declared in a side file ``LOG.timing.toml`` beside ``LOG.csv`` (same stem)::

    [timing]
    default = "instant"      # every channel not named below
    wrench = "mean"          # Fx, Fz, My
    tau = "delay:0.0005"     # tau1…tauN
    tau2 = "mean"            # a single column wins over its group

or on the command line (``torquebench estimate --timing mean|instant|delay:SECONDS``), which
overrides every channel.
"""

from __future__ import annotations

import difflib
from pathlib import Path

import numpy as np

from userio.errors import InputError
from userio.ranges import Range

KINDS = ("instant", "mean", "delay")
DELAY_RANGE = Range(0.0, 1.0, "s", high="a sensor filter's group delay is micro- to milliseconds: "
                    "ms or samples typed as seconds?")


def spec(text) -> tuple[str, float]:
    """'instant' | 'mean' | 'delay:SECONDS' → (kind, delay_s); ValueError saying what is wrong."""
    if not isinstance(text, str):
        raise ValueError(f"expected 'instant', 'mean' or 'delay:SECONDS', got {text!r}")
    s = text.strip().lower()
    if s in ("instant", "mean"):
        return s, 0.0
    if s.startswith("delay:"):
        try:
            d = float(s[6:])
        except ValueError:
            d = float("nan")
        if not (np.isfinite(d) and d >= 0):
            raise ValueError(f"group delay must be a finite number of seconds ≥ 0, got {text!r}")
        why = DELAY_RANGE.problem(d)
        if why:
            raise ValueError(f"group delay {why}")
        return "delay", d
    hint = difflib.get_close_matches(s.split(":")[0], ["instant", "mean", "delay"], n=1)
    did = f" (did you mean '{hint[0]}'?)" if hint else ""
    raise ValueError(f"unknown timing {text!r}{did}; use 'instant', 'mean' or 'delay:SECONDS'")


def parse(text, where: str) -> tuple[str, float]:
    """:func:`spec` with InputError naming ``where`` (a --timing option)."""
    try:
        return spec(text)
    except ValueError as exc:
        raise InputError(f"{where}: {exc}") from None


def channel_names(n_links: int) -> list[str]:
    return ["Fx", "Fz", "My", *[f"tau{i}" for i in range(1, n_links + 1)]]


def uniform(spec, n_links: int, where: str = "--timing") -> list[tuple[str, float]]:
    """One declaration for every channel."""
    kind = parse(spec, where) if isinstance(spec, str) else tuple(spec)
    return [kind] * (n_links + 3)


def side_file(log_path) -> Path:
    """``LOG.timing.toml`` for ``LOG.csv`` / ``LOG.parquet``."""
    p = Path(log_path)
    return p.with_name(p.stem + ".timing.toml")


def describe(spec) -> str:
    """'mean' when every channel agrees, else 'Fx=mean, …'."""
    if spec is None:
        return "instant"
    texts = [k if k != "delay" else f"delay:{d:g}" for k, d in spec]
    if len(set(texts)) == 1:
        return texts[0]
    return ", ".join(f"{n}={t}" for n, t in zip(channel_names(len(spec) - 3), texts))


def is_instant(spec) -> bool:
    return spec is None or all(k == "instant" for k, _ in spec)


def step_mean_correction(tauT: np.ndarray, spec, dt_s: float) -> np.ndarray:
    """τ̄_k − (τ_k + τ_{k+1})/2 per channel, (n, T−1): what the declared sampling adds to the
    trapezoid the observer uses for instantaneous readings (zero rows for ``instant``)."""
    n, T = tauT.shape
    corr = np.zeros((n, max(T - 1, 0)))
    if T < 2 or spec is None:
        return corr
    trap = 0.5 * (tauT[:, 1:] + tauT[:, :-1])
    for j, (kind, delay) in enumerate(spec):
        if kind == "mean":
            corr[j] = tauT[j, 1:] - trap[j]
        elif kind == "delay" and delay > 0:
            x = tauT[j]
            s = delay / dt_s
            i0 = int(np.floor(s))
            f = s - i0
            idx = np.minimum(np.arange(T) + i0, T - 1)
            idx1 = np.minimum(idx + 1, T - 1)
            aligned = (1 - f) * x[idx] + f * x[idx1]
            corr[j] = 0.5 * (aligned[1:] + aligned[:-1]) - trap[j]
    return corr
