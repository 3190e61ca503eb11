"""Plausibility of a sensor log beyond its syntax: units and sampling a robot can produce.

Checked (``check_log``, called by ``estimator.log.read_log``):
- sampling period Δt = median(t_{k+1} − t_k) in [10 µs, 1 s] (else InputError; a period of
  ~1 usually means time in milliseconds, < 10 µs microseconds or nanoseconds);
- joint angles |q_i| ≤ 2π (a leg joint never turns a full revolution; larger angles look like
  degrees) → InputError;
- velocities consistent with the angles: the least-squares scale s of the finite differences
  on the logged velocities, Δq/Δt ≈ s · ½(q̇_k + q̇_{k+1}), computed when the two are strongly
  correlated (r ≥ 0.9: real motion, not noise). s ≈ 1 is consistent; s off by more than 10×
  → InputError naming the likely unit mix-up (57.3: angles in degrees; 1/57.3: velocities in
  deg/s; 10⁻³: time in ms); s outside [0.5, 2] → a warning.
Backwards, duplicate and irregular time steps are refused by ``read_log`` itself.
Warnings are returned, stored on ``log.plausibility_warnings`` and issued as
:class:`PlausibilityWarning`.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from userio.errors import InputError

DT_MIN_S, DT_MAX_S = 10e-6, 1.0
MAX_JOINT_ANGLE_RAD = 2 * math.pi
MIN_CORRELATION = 0.9


class PlausibilityWarning(UserWarning):
    """A log that is readable but looks odd (the message says what)."""


def _unit_hint(scale: float) -> str:
    hints = {180 / math.pi: "angles look like degrees while velocities are rad/s",
             math.pi / 180: "velocities look like deg/s while angles are rad",
             1e-3: "time looks like milliseconds", 1e3: "time looks like kiloseconds or velocities "
             "like mrad/s", 1e-6: "time looks like microseconds"}
    best = min(hints, key=lambda h: abs(math.log(scale / h)))
    return hints[best] if abs(math.log(scale / best)) < math.log(1.5) else "units do not match"


def velocity_scale(t: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[float, float]:
    """(s, r): least-squares scale of Δq/Δt on the mid-step velocity, and their correlation."""
    if len(t) < 3:
        return float("nan"), float("nan")
    fd = np.diff(q, axis=0) / np.diff(t)[:, None]
    mid = 0.5 * (dq[1:] + dq[:-1])
    fd, mid = fd.ravel(), mid.ravel()
    den = float(mid @ mid)
    if den == 0 or float(fd @ fd) == 0:
        return float("nan"), float("nan")
    s = float(fd @ mid) / den
    r = float(fd @ mid) / math.sqrt(den * float(fd @ fd))
    return s, r


class Checker:
    """The same checks on a log read in chunks: ``rows`` per chunk (angles; the velocity sums,
    including the step across the chunk boundary), ``period`` once the period is known, and
    ``finish`` for the velocity scale over the whole log (from running sums)."""

    def __init__(self, source: str, floating: bool, n_links: int):
        self.src, self.base, self.n = source, 0 if floating else 3, n_links
        self.sums = np.zeros(3)            # Σ fd·mid, Σ mid·mid, Σ fd·fd
        self.steps = 0
        self._last = None                  # (t, q, dq) of the previous chunk's last row

    def rows(self, t, q, dq):
        from estimator import kernels

        t, q, dq = np.asarray(t, float), np.asarray(q, float), np.asarray(dq, float)
        if kernels.available() and len(t):             # the same checks and sums in one pass
            k, j = kernels.plausibility_rows(t, q, dq, self.base, self.n, MAX_JOINT_ANGLE_RAD,
                                             self._last, self.sums)
            if k >= 0:
                self._angle_error(t, q[:, 3:3 + self.n], k, j)
            self.steps += len(t) - (0 if self._last is not None else 1)
            self._last = (t[-1], q[-1:, self.base:].copy(), dq[-1:, self.base:].copy())
            return
        joints = q[:, 3:3 + self.n]
        if joints.size:
            big = np.abs(joints) > MAX_JOINT_ANGLE_RAD
            if big.any():
                self._angle_error(t, joints, *np.argwhere(big)[0])
        qq, dd = q[:, self.base:], dq[:, self.base:]
        if self._last is not None:
            t0, q0, d0 = self._last
            t, qq, dd = np.r_[t0, t], np.vstack([q0, qq]), np.vstack([d0, dd])
        if len(t) > 1:
            fd = np.diff(qq, axis=0)
            fd /= np.diff(t)[:, None]
            mid = dd[1:] + dd[:-1]
            mid *= 0.5
            self.sums += [float(np.einsum("ij,ij->", fd, mid)), float(np.einsum("ij,ij->", mid, mid)),
                          float(np.einsum("ij,ij->", fd, fd))]
            self.steps += len(t) - 1
        self._last = (t[-1], qq[-1:].copy(), dd[-1:].copy())

    def _angle_error(self, t, joints, k, j):
        raise InputError(f"{self.src}: column 'q{j + 1}': joint angle {joints[k, j]:g} rad "
                         f"at t = {t[k]:g} s exceeds 2π; angles look like degrees (the log "
                         "must be in rad)")

    def period(self, dt: float):
        if not DT_MIN_S * (1 - 1e-6) <= dt <= DT_MAX_S * (1 + 1e-6):   # rounding of t
            hint = (" (time in milliseconds?)" if 1.0 < dt <= 1e3 else
                    " (time in µs or ns?)" if dt < DT_MIN_S else "")
            raise InputError(f"{self.src}: column 't': sampling period {dt:.4g} s is outside the "
                             f"plausible 10 µs–1 s{hint}; the log's time must be in seconds")

    def scale(self) -> tuple[float, float]:
        """(s, r) as ``velocity_scale`` over every step seen."""
        fm, mm, ff = self.sums
        if self.steps < 2 or mm == 0 or ff == 0:
            return float("nan"), float("nan")
        return fm / mm, fm / math.sqrt(mm * ff)

    def finish(self, warn: bool = True) -> list[str]:
        found = []
        s, r = self.scale()
        if math.isfinite(s) and r >= MIN_CORRELATION:
            if not 0.1 <= s <= 10:
                raise InputError(f"{self.src}: velocities disagree with the angle differences by a "
                                 f"factor {s:.4g} (Δq/Δt vs logged q̇, correlation {r:.2f}): "
                                 f"{_unit_hint(s)}; the log must be in s, rad, rad/s")
            if not 0.5 <= s <= 2:
                found.append(f"{self.src}: velocities disagree with the angle differences by a "
                             f"factor {s:.3g} (correlation {r:.2f}); check the velocity filter and units")
        if warn:
            for msg in found:
                warnings.warn(msg, PlausibilityWarning, stacklevel=3)
        return found


def check_log(log) -> list[str]:
    """Raise InputError for an implausible log; return (and warn about) what merely looks odd.

    The whole log in one chunk of ``Checker`` (sampling period: ``observer.regular_period``)."""
    from estimator.observer import regular_period

    checker = Checker(log.source, log.floating, log.n_links)
    t = np.asarray(log.t, float)
    if len(t) > 1:
        checker.period(regular_period(t))
    checker.rows(t, log.q, log.dq)
    found = checker.finish(warn=False)
    for msg in found:
        warnings.warn(msg, PlausibilityWarning, stacklevel=2)
    log.plausibility_warnings = found
    return found
