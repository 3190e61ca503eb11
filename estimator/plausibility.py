"""Plausibility of a sensor log beyond its syntax: units and sampling a robot can produce.

Checked (``check_log``, called by ``estimator.log_reader.read_log``):
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

from estimator import compiled
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


def _plausibility_py(t, q, dq, base, n, max_angle, has_last, t0, q0, d0, sums):
    """Checker.rows in one pass: the first (k, j) with |q_j| > max_angle (joint angles) or
    (−1, −1); else the sums Σ fd·mid, Σ mid·mid, Σ fd·fd over the steps of [last] + rows
    (fd = Δq/Δt, mid = ½(q̇_k + q̇_{k+1}), coordinates from ``base`` on) added to ``sums`` (2, 3):
    row 0 the base's coordinates (columns 0–2), row 1 the joints'."""
    T, C = q.shape
    for k in range(T):
        for j in range(n):
            if abs(q[k, 3 + j]) > max_angle:
                return k, j
    acc = np.zeros((2, 3))
    for k in range(-1 if has_last else 0, T - 1):
        ta = t0 if k < 0 else t[k]
        h = t[k + 1] - ta
        for j in range(base, C):
            qa = q0[j - base] if k < 0 else q[k, j]
            da = d0[j - base] if k < 0 else dq[k, j]
            fd = (q[k + 1, j] - qa) / h
            mid = (dq[k + 1, j] + da) * 0.5
            g = 0 if j < 3 else 1
            acc[g, 0] += fd * mid
            acc[g, 1] += mid * mid
            acc[g, 2] += fd * fd
    for g in range(2):
        for i in range(3):
            sums[g, i] += acc[g, i]
    return -1, -1


def plausibility_rows(t, q, dq, base, n, max_angle, last, sums):
    """``_plausibility_py`` compiled; ``last``: (t, q, q̇) of the previous row (coordinates from
    ``base`` on) or None. → (k, j) of the first joint angle beyond ``max_angle``, or (−1, −1).
    Needs ``compiled.available()``."""
    k = _LOOPS.get()
    has = last is not None
    q0 = np.ascontiguousarray(last[1], float).ravel() if has else np.zeros(q.shape[1] - base)
    d0 = np.ascontiguousarray(last[2], float).ravel() if has else np.zeros(q.shape[1] - base)
    return k["plaus"](np.ascontiguousarray(t, float), np.ascontiguousarray(q, float),
                      np.ascontiguousarray(dq, float), int(base), int(n), float(max_angle), has,
                      float(last[0]) if has else 0.0, q0, d0, sums)


_LOOPS = compiled.Loops(lambda: {"plaus": compiled.jit(_plausibility_py)})


class Checker:
    """The same checks on a log read in chunks: ``rows`` per chunk (angles; the velocity sums,
    including the step across the chunk boundary), ``period`` once the period is known, and
    ``finish`` for the velocity scale over the whole log (from running sums)."""

    def __init__(self, source: str, floating: bool, n_links: int):
        self.src, self.base, self.n = source, 0 if floating else 3, n_links
        self.sums = np.zeros((2, 3))       # Σ fd·mid, Σ mid·mid, Σ fd·fd of the base's, the joints' columns
        self.steps = 0
        self._last = None                  # (t, q, dq) of the previous chunk's last row

    def rows(self, t, q, dq):
        t, q, dq = np.asarray(t, float), np.asarray(q, float), np.asarray(dq, float)
        if compiled.available() and len(t):            # the same checks and sums in one pass
            k, j = plausibility_rows(t, q, dq, self.base, self.n, MAX_JOINT_ANGLE_RAD,
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
            nb = 3 - self.base                       # the base's columns among qq (0 or 3)
            for g, cols in ((0, slice(0, nb)), (1, slice(nb, None))):
                f, m = fd[:, cols], mid[:, cols]
                self.sums[g] += [float(np.einsum("ij,ij->", f, m)), float(np.einsum("ij,ij->", m, m)),
                                 float(np.einsum("ij,ij->", f, f))]
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

    def scale(self, group: int | None = None) -> tuple[float, float]:
        """(s, r) as ``velocity_scale`` over every step seen: of the base's (``group`` 0) or the
        joints' (1) coordinates, or of all of them (None)."""
        fm, mm, ff = self.sums.sum(axis=0) if group is None else self.sums[group]
        if self.steps < 2 or mm == 0 or ff == 0:
            return float("nan"), float("nan")
        return fm / mm, fm / math.sqrt(mm * ff)

    def finish(self, warn: bool = True) -> list[str]:
        """The velocity scale per group (base, joints): one group in other units (joint rates in
        deg/s beside a base in m/s) is not hidden by the other's agreement."""
        found = []
        for group, what in ((0, "base velocities"), (1, "joint velocities")):
            s, r = self.scale(group)
            if not (math.isfinite(s) and r >= MIN_CORRELATION):
                continue
            if not 0.1 <= s <= 10:
                raise InputError(f"{self.src}: {what} disagree with the angle differences by a "
                                 f"factor {s:.4g} (Δq/Δt vs logged q̇, correlation {r:.2f}): "
                                 f"{_unit_hint(s)}; the log must be in s, rad, rad/s")
            if not 0.5 <= s <= 2:
                found.append(f"{self.src}: {what} disagree with the angle differences by a "
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


# --------------------------------------------------------------------------- the log vs its robot
HEAD_SAMPLES = 256          # samples of the log's head checked against the robot's dynamics
HEAD_WINDOWS = 8            # sub-windows of the head (a scale is fitted across them)
FAR_SIGMA = 8.0             # a residual beyond this many per-sample noise σ is "far outside"
MODEL_SLACK = 0.05          # and beyond this fraction of what the model expects (model error)


def _channels(n_links: int) -> list[str]:
    return ["Fx", "Fz", "My", *[f"tau{i}" for i in range(1, n_links + 1)]]


def expected_forces(robot, t, q, dq, tau_meas, windows: int = HEAD_WINDOWS):
    """(m, g) per sub-window, shapes (W, n): the mean measured generalized force m (the log's
    [Fx, Fz, My, τ…]) and the one the robot's dynamics needs without contact, from momentum:
    g = (P(t_b) − P(t_a))/(t_b − t_a) − mean(Cᵀq̇ − G), since Ṗ = τ_meas + Cᵀq̇ − G + τ_ext
    (no velocity is differentiated; noise averages out over a window)."""
    from estimator.observer import momentum_terms

    return _expected(lambda q_, v_, tau_: momentum_terms(robot, q_, v_, tau_), t, q, dq, tau_meas, windows)


def _expected(momentum, t, q, dq, tau_meas, windows: int = HEAD_WINDOWS):
    """``expected_forces`` with any model's ``momentum(q, v, τ_meas)`` → (P, u)."""
    t = np.asarray(t, float)
    P, u = momentum(q, dq, tau_meas)                        # u = τ_meas + Cᵀq̇ − G
    model = u - tau_meas                                    # Cᵀq̇ − G
    edges = np.linspace(0, len(t) - 1, windows + 1).round().astype(int)
    m, g = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        if b <= a:
            continue
        dt = t[b] - t[a]
        # trapezoid means over [t_a, t_b]
        w = np.diff(t[a:b + 1])
        mean = lambda x: (0.5 * (x[a:b] + x[a + 1:b + 1]) * w[:, None]).sum(0) / dt   # noqa: E731
        m.append(mean(tau_meas))
        g.append((P[b] - P[a]) / dt - mean(model))
    return np.array(m), np.array(g)


def check_head(robot, log, noise=None, *, expected_contact: bool = False, where: str | None = None) -> list[str]:
    """The first samples of ``log`` (a SensorLog chunk) against ``robot``'s dynamics.

    The mean generalized force the log measures over its first ``HEAD_SAMPLES`` samples is
    compared with what the robot's masses and motion need without contact (``expected_forces``).
    A confident diagnosis of nonsense raises InputError naming it: an all-zero log, a group of
    channels off by 1000× (N·mm, kN, mN), Fx/Fz or two joint torques swapped, a sign flipped,
    angles in degrees. A residual merely far outside the noise (``FAR_SIGMA`` σ and
    ``MODEL_SLACK`` of the expected force) is returned as a warning that names the channel and the
    likely causes (the log starts in contact; units, channels or the robot file do not match),
    as is a channel that is exactly constant (dead) while the model expects it to carry load.
    ``expected_contact`` (a stance foot): refusals become warnings (the ground carries load)."""
    src = where or getattr(log, "source", "log")
    T = min(len(log.t), HEAD_SAMPLES)
    if T < 16:
        return []
    t, q, dq = log.t[:T], log.q[:T], log.dq[:T]
    tau = np.concatenate([log.wrench[:T], log.tau_Nm[:T]], axis=1)
    names = _channels(log.n_links)
    head = f"{src}: the first {T} samples"
    if not np.any(tau):
        raise InputError(f"{head} measure exactly 0 on every force and torque channel (Fx, Fz, My, "
                         "tau…): an empty or all-zero export, or sensors not connected; the robot's "
                         "weight alone loads them")
    with np.errstate(all="ignore"):
        m, g = expected_forces(robot, t, q, dq, tau)
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(g))):
        return []
    sigma = _sigma(noise, log.n_links)
    scale = np.abs(g).max(0)
    tol = np.maximum(FAR_SIGMA * sigma, MODEL_SLACK * scale)
    e = (m - g).mean(0)
    far = np.abs(e) > tol
    if not far.any():
        return []
    found = []
    refuse = []
    # a unit or channel mix-up explains the residual: refuse (unless a contact is expected)
    for diag in (_swapped(m, g, tol, names), _scaled(m, g, tol, names, far),
                 _degrees(robot, t, q, dq, tau, g, tol, far)):
        if diag:
            refuse.append(diag)
    if refuse:
        msg = f"{head}: {refuse[0]}"
        if not expected_contact:
            raise InputError(msg)
        found.append(msg)
    dead = [j for j in np.flatnonzero(far) if np.ptp(tau[:, j]) == 0]
    for j in dead:
        found.append(f"{head}: channel {names[j]} is constant ({tau[0, j]:g}) while the robot's "
                     f"dynamics need {g[:, j].mean():.4g} there: a dead or unplugged channel?")
    if not dead and not expected_contact:       # a stance foot carries load from the start
        j = int(np.argmax(np.abs(e) / tol))
        found.append(f"{head}: the measured {names[j]} ({m[:, j].mean():.4g}) differs from what the "
                     f"robot's masses and motion need without contact ({g[:, j].mean():.4g}) by "
                     f"{abs(e[j]) / sigma[j]:.0f} σ: the log starts in contact, or its units or channels "
                     "or the robot file (--robot) do not match the log")
    return found


def _sigma(noise, n_links: int) -> np.ndarray:
    """Per-channel noise σ [Fx, Fz, My, τ…] (the paper leg's sensors when none is given)."""
    if noise is None:
        ft, tq = np.array([0.1, 0.1, 0.01]), np.full(n_links, 0.005)
    else:
        ft = np.asarray(noise.ft_sigma, float)
        tq = np.broadcast_to(np.asarray(noise.torque_sigma_Nm, float), (n_links,))
    return np.concatenate([ft, tq])


def _groups(n: int) -> list[tuple[str, list[int], dict]]:
    force = {1e3: "mN instead of N", 1e-3: "kN instead of N", -1.0: "the sign flipped (the wrench "
             "is the mount's ON the base, docs/conventions.md)"}
    moment = {1e3: "N·mm instead of N·m", 1e-3: "kN·m instead of N·m", -1.0: "the sign flipped"}
    torque = {1e3: "N·mm instead of N·m", 1e-3: "kN·m instead of N·m", -1.0: "the sign flipped "
              "(joint torques act ON the link, docs/conventions.md)"}
    return [("the base forces Fx, Fz", [0, 1], force), ("the base moment My", [2], moment),
            ("the joint torques " + ", ".join(f"tau{i}" for i in range(1, n + 1)),
             list(range(3, 3 + n)), torque)]


def attach_warnings(summary: dict, found: list[str]) -> None:
    """What a log's checks found, into a command's ``summary["warnings"]`` and as
    PlausibilityWarnings (the CLI prints them on stderr); nothing when nothing was found."""
    if not found:
        return
    import warnings

    summary["warnings"] = list(found)
    for w in found:
        warnings.warn(w, PlausibilityWarning, stacklevel=3)


def check_head_model(model, log, noise=None, where: str | None = None) -> list[str]:
    """``check_head`` for any RobotModel (a URDF robot's 3-D log, estimator.spatial.logs): the
    mean generalized force the first samples measure (base rows from the FT sensor, sensed joint
    torques) against what the model's masses and motion need without contact. A group of rows
    off by 1000× or with its sign flipped, or an all-zero log, is refused naming it; a row far
    outside the noise is a warning."""
    src = where or getattr(log, "source", "log")
    T = min(len(log.t), HEAD_SAMPLES)
    if T < 16:
        return []
    head = f"{src}: the first {T} samples"
    if not (np.any(log.wrench[:T]) or np.any(log.tau_Nm[:T])):
        raise InputError(f"{head} measure exactly 0 on every force, moment and torque channel: an "
                         "empty or all-zero export, or sensors not connected; the robot's weight alone "
                         "loads them")
    t, q, v = log.t[:T], log.q[:T], log.v[:T]
    tau = log.tau_meas(model)[:T]
    with np.errstate(all="ignore"):
        m, g = _expected(model.momentum_terms, t, q, v, tau)
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(g))):
        return []
    nb = model.n_base
    rows = list(range(nb)) + [nb + j for j, s in enumerate(model.sensed_joints) if s]
    m, g = m[:, rows], g[:, rows]
    ft = np.full(6, np.nan) if noise is None else np.asarray(noise.ft_sigma, float)
    tq = np.full(len(rows) - nb, 0.005) if noise is None else \
        np.broadcast_to(np.asarray(noise.torque_sigma_Nm, float), (len(rows) - nb,))
    ft = np.where(np.isfinite(ft), ft, [0.1, 0.1, 0.1, 0.01, 0.01, 0.01])
    sigma = np.concatenate([ft[:nb], tq])
    names = ["F_x", "F_y", "F_z", "M_x", "M_y", "M_z"][:nb] + \
        [n for n, s in zip(model.joint_names, model.sensed_joints) if s]
    tol = np.maximum(FAR_SIGMA * sigma, MODEL_SLACK * np.abs(g).max(0))
    e = (m - g).mean(0)
    far = np.abs(e) > tol
    if not far.any():
        return []
    force = {1e3: "mN instead of N", 1e-3: "kN instead of N", -1.0: "the sign flipped (the wrench "
             "is the one ON the robot, in the sensor frame: docs/conventions.md)"}
    moment = {1e3: "N·mm instead of N·m", 1e-3: "kN·m instead of N·m", -1.0: "the sign flipped"}
    groups = [("the FT sensor's forces", [0, 1, 2], force), ("the FT sensor's moments", [3, 4, 5], moment),
              ("the joint torques", list(range(nb, len(rows))), dict(moment))]
    diag = _scaled(m, g, tol, names, far, groups)
    if diag:
        raise InputError(f"{head}: {diag}")
    j = int(np.argmax(np.abs(e) / tol))
    return [f"{head}: the measured {names[j]} ({m[:, j].mean():.4g}) differs from what the robot's "
            f"masses and motion need without contact ({g[:, j].mean():.4g}) by {abs(e[j]) / sigma[j]:.0f} σ: "
            "the log starts in contact, or its units or channels or the robot file (--robot) do not "
            "match the log"]


def _scaled(m, g, tol, names, far, groups=None) -> str | None:
    """A group of channels measuring k·(what the model needs), k ≈ 1000, 1/1000 or −1."""
    for label, idx, hints in (groups or _groups(len(names) - 3)):
        if not idx:
            continue
        if not far[idx].any():
            continue
        gg, mm = g[:, idx].ravel(), m[:, idx].ravel()
        den = float(gg @ gg)
        if den <= (tol[idx] ** 2).sum() * len(g):          # the model expects ~nothing here
            continue
        k = float(mm @ gg) / den
        fit = np.abs(m[:, idx] - k * g[:, idx]).mean(0)
        for ref, hint in hints.items():
            if k != 0 and abs(np.log(abs(k) / abs(ref))) < np.log(2) and np.sign(k) == np.sign(ref) \
                    and np.all(fit <= np.maximum(np.abs(k) * tol[idx], 0.2 * np.abs(m[:, idx]).mean(0))):
                return (f"{label} are {k:.3g} × what the robot's masses and motion need: {hint}? "
                        "The log must be in SI units (N, N·m)")
    return None


def _swapped(m, g, tol, names) -> str | None:
    """Two channels exchanged: swapping them back explains the residual."""
    n = len(names)
    pairs = [(0, 1)] + [(a, b) for a in range(3, n) for b in range(a + 1, n)][:15]
    base = np.abs(m - g).mean(0)
    for a, b in pairs:
        mm = m.copy()
        mm[:, [a, b]] = mm[:, [b, a]]
        fixed = np.abs(mm - g).mean(0)
        if max(base[a], base[b]) > 4 * max(tol[a], tol[b]) and fixed[a] <= tol[a] and fixed[b] <= tol[b]:
            return (f"{names[a]} and {names[b]} look swapped (exchanged, both match what the robot "
                    "needs); check the log's column order")
    return None


def _degrees(robot, t, q, dq, tau, g, tol, far) -> str | None:
    """Angles in degrees: the robot's needs at q·π/180 explain the log far better."""
    if not np.any(np.abs(q[:, 3:]) > 0.5):
        return None
    k = np.pi / 180
    qq, dd = q.copy(), dq.copy()
    qq[:, 2:] *= k
    dd[:, 2:] *= k
    with np.errstate(all="ignore"):
        m2, g2 = expected_forces(robot, t, qq, dd, tau)
    if not np.all(np.isfinite(g2)):
        return None
    before = np.abs(m2 - g).mean(0)
    after = np.abs(m2 - g2).mean(0)
    if np.all(after <= tol) and np.any(before[far] > 4 * tol[far]):
        return ("the joint angles look like degrees (read as degrees, the robot's gravity torques "
                "match the log); the log must be in rad and rad/s")
    return None


WHOLE_LOG_FRACTION = 0.9


def whole_log_contact(summary: dict, head_warnings=()) -> str | None:
    """A warning when contact is reported over ≥ 90 % of the samples from the first one: a real
    contact rarely spans a whole log; a unit, channel or robot-file mix-up always does."""
    n, k = summary.get("samples") or 0, summary.get("contact_samples") or 0
    ivs = summary.get("intervals") or []
    if n < 16 or k < WHOLE_LOG_FRACTION * n or not ivs:
        return None
    return (f"{summary.get('log', 'log')}: contact over {100 * k / n:.0f} % of the samples, from the "
            "first one: check the log's units and channel order and the robot file (--robot)"
            + ("" if head_warnings else "; a contact held over the whole log is rare"))
