"""Live acquisition over serial (pyserial): raw capture first, then parsing; guided sessions.

Every chunk read from the port is appended to ``RAW.part`` and flushed *before* it is parsed, so
a parser failure loses nothing; on success the file is fsynced and renamed to ``RAW``.
A guided static-loading session prompts for each mass, drains what arrived while the user was
placing it, discards a settling period, then averages a window of samples that passes the
settling test |mean(2nd half) − mean(1st half)| ≤ max(4·2σ√(τ/W), tol) (4 standard errors of the
difference; τ the noise's integrated autocorrelation time, 1 for white noise), sliding forward
until it does or ``max_wait`` samples have passed. Every figure of a window (mean, noise, step)
carries its standard error with the autocorrelation taken into account (:func:`window_stats`).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from userio.errors import InputError
from calibration.frames import FrameParser


def open_port(port: str, baud: int = 2_000_000, timeout_s: float = 0.05):
    """Open ``port`` (a device path or a pyserial URL such as ``loop://``)."""
    import serial

    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=timeout_s)
    except (serial.SerialException, ValueError) as exc:
        raise InputError(f"--port: cannot open {port!r}: {exc}") from None


class RawCapture:
    """Append-only raw byte log ``path.part`` → moved to ``path`` on :meth:`close`.

    An existing ``.part`` (kept by an interrupted run) is appended to, never truncated, and the
    resumed byte count is ``resumed``; a ``.part`` that is a symlink (or not a regular file) is
    refused rather than followed onto another file."""

    @staticmethod
    def part_path(path) -> Path:
        path = Path(path)
        return path.with_name(path.name + ".part")

    def __init__(self, path, *, force: bool = False):
        self.path = Path(path)
        self.force = force
        if os.path.lexists(self.path) and not force:
            raise InputError(f"--out: {self.path} exists; refusing to overwrite it (use --force)")
        if not self.path.parent.is_dir():
            raise InputError(f"--out: directory {self.path.parent} does not exist")
        self.part = self.part_path(self.path)
        if os.path.islink(self.part):
            raise InputError(f"--out: {self.part} (the capture file) is a symlink; refusing to follow "
                             "it onto another file: remove it or choose another --out")
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | getattr(os, "O_NOFOLLOW", 0)
        try:
            fd = os.open(self.part, flags, 0o644)
        except OSError as exc:
            raise InputError(f"--out: cannot open the capture file {self.part}: {exc.strerror}") from None
        st = os.fstat(fd)
        import stat as _stat
        if not _stat.S_ISREG(st.st_mode):
            os.close(fd)
            raise InputError(f"--out: {self.part} (the capture file) is not a regular file")
        self.resumed = int(st.st_size)
        self.fh = os.fdopen(fd, "ab")
        self.n_bytes = 0

    def write(self, data: bytes) -> None:
        self.fh.write(data)
        self.fh.flush()
        self.n_bytes += len(data)

    def close(self) -> Path:
        from userio import outputs

        self.fh.flush()
        os.fsync(self.fh.fileno())
        self.fh.close()
        plan = outputs.current()
        mode = plan.admit(self.path, final=True) if plan is not None else (
            "replace" if self.force else "new")
        outputs.place(self.part, self.path, mode)
        return self.path

    def abort(self) -> None:
        """Close but keep ``.part`` (the bytes captured so far are never lost)."""
        if not self.fh.closed:
            self.fh.flush()
            self.fh.close()


@dataclass
class Reader:
    """Port + raw log + parser; ``read()`` returns newly parsed (seq, samples)."""

    port: object
    raw: RawCapture
    parser: FrameParser
    chunk: int = 4096
    seq_log: list = field(default_factory=list)
    sample_log: list = field(default_factory=list)
    keep: bool = False

    def drain(self) -> None:
        """Read (log and parse, discard samples) what is waiting now, without blocking on more."""
        waiting = getattr(self.port, "in_waiting", 0) or 0
        if waiting:
            self.read(waiting)

    def read(self, n_bytes: int | None = None):
        data = self.port.read(n_bytes if n_bytes is not None
                              else max(self.chunk, getattr(self.port, "in_waiting", 0) or 0))
        if not data:
            return None
        self.raw.write(data)                      # on disk before parsing
        seq, samples = self.parser.feed(data)
        if self.keep and seq.size:
            self.seq_log.append(seq)
            self.sample_log.append(samples)
        return seq, samples


def capture(reader: Reader, *, n_frames: int | None = None, duration_s: float | None = None,
            idle_timeout_s: float = 2.0, clock=time.monotonic) -> None:
    """Read until ``n_frames`` frames, ``duration_s`` seconds, or no bytes for ``idle_timeout_s``."""
    start = last = clock()
    target = reader.parser.stats.frames + n_frames if n_frames else None
    while True:
        got = reader.read()
        now = clock()
        if got is not None:
            last = now
        elif now - last > idle_timeout_s:
            break
        if target is not None and reader.parser.stats.frames >= target:
            break
        if duration_s is not None and now - start >= duration_s:
            break


def _collect(reader: Reader, n: int, channel: int, idle_timeout_s: float, clock) -> np.ndarray:
    """Next ``n`` samples of ``channel`` (InputError if the stream stops)."""
    out, have, last = [], 0, clock()
    while have < n:
        got = reader.read()
        if got is None or got[0].size == 0:
            if clock() - last > idle_timeout_s:
                raise InputError(f"--port: no valid frames for {idle_timeout_s:g} s "
                                 f"(got {have} of {n} samples)")
            continue
        last = clock()
        out.append(got[1][:, channel])
        have += got[0].size
    return np.concatenate(out)[:n] if out else np.zeros(0)


def autocorr_times(x: np.ndarray, c: float = 5.0) -> tuple[float, float, bool]:
    """(τ, τ₂, resolved): integrated autocorrelation times of ``x`` for its mean and its variance.

    ρ_k from the FFT autocovariance, τ = 1 + 2 Σ_{k=1}^{M} ρ_k and τ₂ = 1 + 2 Σ_{k=1}^{M} ρ_k², with
    Sokal's window M = the smallest lag ≥ c·τ(M). Then Var(mean) = σ² τ / n and, for Gaussian
    noise, Var(s²) ≈ 2 σ⁴ τ₂ / n. Both are clipped at 1 (never more than n independent samples).
    ``resolved`` is False when no such M exists below n/2 or n < 50 τ (τ then underestimated)."""
    x = np.asarray(x, float)
    n = x.size
    if n < 8:
        return 1.0, 1.0, False
    y = x - x.mean()
    f = np.fft.rfft(y, n=2 * n)
    acov = np.fft.irfft(f * np.conjugate(f))[:n]
    if acov[0] <= 0:
        return 1.0, 1.0, False
    rho = acov / acov[0]
    tau = 2.0 * np.cumsum(rho) - 1.0                 # τ(M) = 1 + 2 Σ_{k=1}^{M} ρ_k
    ok = np.arange(n) >= c * tau
    m = int(np.argmax(ok)) if ok[: n // 2].any() else n // 2
    resolved = bool(ok[: n // 2].any())
    t1 = float(tau[m])
    t2 = float(2.0 * np.sum(rho[: m + 1] ** 2) - 1.0)
    return max(t1, 1.0), max(t2, 1.0), resolved and n >= 50 * t1


def _detrend(x: np.ndarray) -> np.ndarray:
    """Residuals of the least-squares line through ``x`` (the noise, without a slow drift)."""
    t = np.arange(x.size, dtype=float)
    return x - np.polyval(np.polyfit(t, x, 1), t)


def window_stats(x: np.ndarray, tol: float = 0.0) -> dict:
    """Mean reading, its noise and the settling test of one window, each with its error estimate.

    τ, τ₂ (:func:`autocorr_times`) of the window give the standard errors of the mean and of the
    noise; a drift inflates them, which is honest (a drifting mean is not a stable figure). The
    settling test takes σ_d, τ_d of the linearly detrended window instead, so a drift is not
    mistaken for correlated noise (which would widen the limit and let the ramp through).

        mean      x̄ ± s √(τ/W)                        (standard error, 1σ; n_eff = W/τ)
        noise     s ± s √(τ₂ / (2W))                   (standard error of the std, 1σ, Gaussian)
        step      |x̄₂ − x̄₁| (window halves), SE_step = 2 σ_d √(τ_d/W)
        settled   step ≤ max(4 SE_step, tol)           (white noise: 8σ/√W, the former test)

    τ estimated from the window itself is biased low when the window holds fewer than ~100 τ
    samples (``autocorr_resolved`` False): the standard errors are then underestimates.
    """
    x = np.asarray(x, float)
    w = x.size
    h = w // 2
    sd = float(np.std(x, ddof=1))
    tau, tau2, resolved = autocorr_times(x)
    resolved = resolved and w >= 100 * tau
    r = _detrend(x)
    sd_d = float(np.std(r, ddof=2)) if w > 2 else sd
    tau_d, _, _ = autocorr_times(r)
    step = abs(float(x[h:].mean() - x[:h].mean()))
    se_step = 2.0 * sd_d * np.sqrt(tau_d / w)
    threshold = max(4.0 * se_step, tol)
    note = "" if resolved else "; window < 100 τ: τ and so this error are underestimated"
    return {
        "settled": bool(step <= threshold), "mean": float(x.mean()), "std": sd,
        "mean_se": float(sd * np.sqrt(tau / w)),
        "mean_se_method": (f"standard error of the mean, 1σ: s √(τ/n), n = {w} samples, integrated "
                           f"autocorrelation time τ = {tau:.3g} samples (n_eff = {w / tau:.0f}; FFT "
                           f"autocorrelation, Sokal window){note}"),
        "std_se": float(sd * np.sqrt(tau2 / (2.0 * w))),
        "std_se_method": (f"standard error of the standard deviation, 1σ: s √(τ₂/(2n)), τ₂ = 1 + 2Σρ² = "
                          f"{tau2:.3g} (Gaussian noise){note}"),
        "step": step, "step_se": float(se_step), "threshold": float(threshold),
        "step_se_method": (f"standard error of the difference of the window halves' means, 1σ: 2 σ_d √(τ_d/n) "
                           f"(detrended window, τ_d = {tau_d:.3g}); settled when step ≤ max(4 SE, tolerance)"),
        "autocorr_time": float(tau), "n_effective": float(w / tau), "autocorr_resolved": resolved,
    }


def settled_mean(x: np.ndarray, tol: float = 0.0) -> tuple[bool, float, float]:
    """(settled, mean, std) of a window; settled per :func:`window_stats`."""
    s = window_stats(x, tol)
    return s["settled"], s["mean"], s["std"]


def guided_session(reader: Reader, masses_g, *, settle_samples: int, window_samples: int,
                   max_wait_samples: int | None = None, repeats: int = 1, unload: bool = False,
                   channel: int = 0, tol_counts: float = 0.0, prompt=input, out=sys.stderr,
                   idle_timeout_s: float = 2.0, clock=time.monotonic) -> list[dict]:
    """Prompt for each mass and average a settled window; returns one row per reading.

    At the prompt: Enter accepts the listed mass, a number is the mass actually placed (g),
    ``q`` aborts (InputError; the raw capture is kept).
    """
    masses = [float(m) for m in masses_g]
    order = [(m, "load") for m in masses]
    if unload:
        order += [(m, "unload") for m in masses[::-1][1:]]
    max_wait = max_wait_samples or 10 * window_samples
    rows = []
    t0 = clock()
    for rep in range(repeats):
        for mass, direction in order:
            answer = prompt(f"[repeat {rep + 1}/{repeats}] place {mass:g} g ({direction}), "
                            "then press Enter (or type the actual mass in g, q to quit): ").strip()
            if answer.lower() in ("q", "quit"):
                raise InputError("guided session aborted by the user")
            if answer:
                try:
                    mass = float(answer)
                except ValueError:
                    raise InputError(f"guided session: {answer!r} is not a mass in g") from None
                if mass < 0:
                    raise InputError(f"guided session: negative mass {mass:g} g")
            reader.drain()                            # what arrived during the prompt
            _collect(reader, settle_samples, channel, idle_timeout_s, clock)
            x = _collect(reader, window_samples, channel, idle_timeout_s, clock)
            waited = 0
            st = window_stats(x, tol_counts)
            while not st["settled"] and waited < max_wait:
                step = max(window_samples // 4, 1)
                x = np.concatenate([x[step:], _collect(reader, step, channel, idle_timeout_s, clock)])
                waited += step
                st = window_stats(x, tol_counts)
            ok, mean, sd = st["settled"], st["mean"], st["std"]
            print(f"  {mass:g} g {direction}: mean {mean:.1f} ± {st['mean_se']:.2g} counts, noise "
                  f"{sd:.1f} ± {st['std_se']:.2g} counts (τ = {st['autocorr_time']:.3g} samples), step "
                  f"{st['step']:.2g} ± {st['step_se']:.2g} (limit {st['threshold']:.2g})"
                  + ("" if ok else "  (NOT settled; recorded with settled=0)"), file=out)
            rows.append({"mass_g": mass, "reading": mean, "direction": direction, "repeat": rep,
                         "timestamp": clock() - t0, "settled": int(ok), "std": sd,
                         "n_samples": int(x.size), "stats": st})
    return rows


def session_csv(rows: list[dict], *, sensor_id: str, lever_arm_m: float | None,
                reading_unit: str = "counts", source: str = "") -> str:
    """Session CSV text (the format of :mod:`calibration.session`) for guided rows."""
    cols = ["mass_g", "reading", "direction", "repeat", "timestamp", "sensor_id", "settled",
            "std", "n_samples"] + (["lever_arm_m"] if lever_arm_m is not None else [])
    lines = [f"# reading_unit={reading_unit}; acquired={source}", ",".join(cols)]
    for r in rows:
        vals = [f"{r['mass_g']:.6g}", f"{r['reading']:.6f}", r["direction"], str(r["repeat"]),
                f"{r['timestamp']:.3f}", sensor_id, str(r["settled"]), f"{r['std']:.4f}",
                str(r["n_samples"])] + ([f"{lever_arm_m:.9g}"] if lever_arm_m is not None else [])
        lines.append(",".join(vals))
    return "\n".join(lines) + "\n"
