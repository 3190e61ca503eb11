"""The momentum observer on a URDF robot: the exact discretization of estimator.observer (its
``residual_window``, generic over rows) on (P, u) of the UrdfModel, offline on a log read in
chunks and streaming one sample at a time.

Rows: base force (world), base moment about the base origin (base frame), joints. Unsensed
joints have no measured torque, so their rows are not an equation: they are computed (u lacks
the actuator torque) and left out of detection and localization (``used_rows``).
"""

from __future__ import annotations

import numpy as np

from estimator import observer as obs
from estimator.errors import InputError


def used_rows(model) -> np.ndarray:
    """Indices of the residual rows that are equations: the six base rows, sensed joints."""
    return np.r_[np.arange(6), 6 + np.flatnonzero(model.sensed_joints)].astype(int)


def gains(model, gain_per_s) -> np.ndarray:
    n = model.n_v
    K = np.broadcast_to(np.asarray(gain_per_s, float), (n,)).copy() if np.ndim(gain_per_s) == 0 \
        else np.asarray(gain_per_s, float)
    if K.shape != (n,) or not np.all(np.isfinite(K)) or np.any(K <= 0):
        raise InputError(f"gain: expected one value or {n} values, each finite and > 0 s^-1")
    return K


class ObserverRun:
    """The offline observer over chunks: ``feed(t, q, v, tau_meas)`` → r (T, nv) of the rows
    finalized now (a group delay holds ``lookahead_rows`` back until the next chunk / final)."""

    def __init__(self, model, gain_per_s, dt_s: float, method: str = "exact", timing=None):
        self.model, self.K, self.dt, self.method, self.timing = model, gains(model, gain_per_s), dt_s, method, timing
        self.ahead = obs.lookahead_rows(timing, dt_s)
        self.prev = None
        self.pending = None

    def feed(self, t, q, v, tau, final: bool = False):
        if self.pending is not None:
            pt, pq, pv, ptau = self.pending
            t, q, v, tau = np.r_[pt, t], np.vstack([pq, q]), np.vstack([pv, v]), np.vstack([ptau, tau])
            self.pending = None
        T = len(t)
        keep = 0 if final else min(self.ahead, T)
        if T == 0 or T == keep:
            self.pending = (t, q, v, tau) if T else None
            return None
        P, u = self.model.momentum_terms(q, v, tau)
        PT, uT, tauT = P.T, u.T, tau.T
        if self.prev is not None:
            t0, P0, u0, tau0, r0 = self.prev
            tw = np.r_[t0, t]
            PT, uT, tauT = (np.concatenate([x0[:, None], x], axis=1) for x0, x in
                            ((P0, PT), (u0, uT), (tau0, tauT)))
        else:
            tw, r0 = t, np.zeros(self.K.size)
        rT = obs.residual_window(tw, np.ascontiguousarray(PT), np.ascontiguousarray(uT),
                                 np.ascontiguousarray(tauT), self.K, self.dt, self.method,
                                 self.timing, r0)
        off = 1 if self.prev is not None else 0
        m = T - keep
        last = off + m - 1
        self.prev = (tw[last], PT[:, last].copy(), uT[:, last].copy(), tauT[:, last].copy(),
                     rT[:, last].copy())
        if keep:
            self.pending = (t[m:], q[m:], v[m:], tau[m:])
        return {"t": t[:m], "q": q[:m], "v": v[:m], "tau": tau[:m], "r": rT[:, off:off + m].T}


def residual(model, t, q, v, tau, gain_per_s=100.0, method="exact", timing=None, dt_s=None):
    """r (T, nv) of a whole log (one chunk)."""
    dt_s = obs.regular_period(t) if dt_s is None else dt_s
    run = ObserverRun(model, gain_per_s, dt_s, method, timing)
    return run.feed(np.asarray(t, float), q, v, tau, final=True)["r"]


class StreamingObserver:
    """One sample at a time: ``step(q, v, tau_meas)`` → r (nv,). The compiled recursion for
    (P, u) on one sample, then r_{k+1} = a r_k + b ((P_{k+1} − P_k)/Δt − (u_k + u_{k+1})/2)."""

    def __init__(self, model, dt_s: float, gain_per_s=100.0):
        self.model = model
        self.K = gains(model, gain_per_s)
        self.dt = float(dt_s)
        self.a, self.b = obs.coefficients(self.K, self.dt, "exact")
        self._q = np.zeros((1, 7 + len(model.joint_names)))
        self._v = np.zeros((1, model.n_v))
        self._tau = np.zeros((1, model.n_v))
        self._P = np.zeros((1, model.n_v))
        self._u = np.zeros((1, model.n_v))
        self._prev = None
        self.r = np.zeros(model.n_v)
        from estimator.spatial import tree as tree_mod

        self._kernel = tree_mod._kernel()
        tr = model.tree
        self._args = (tr.parent, tr.Rp, tr.pp, tr.axis, tr.kind, tr.mass, tr.com, tr.Ic, tr.gravity)

    def step(self, q, v, tau_meas) -> np.ndarray:
        self._q[0], self._v[0], self._tau[0] = q, v, tau_meas
        self._kernel(self._q, self._v, self._tau, *self._args, self._P, self._u)
        P, u = self._P[0].copy(), self._u[0].copy()
        if self._prev is not None:
            P0, u0 = self._prev
            self.r = self.a * self.r + self.b * ((P - P0) / self.dt - 0.5 * (u + u0))
        self._prev = (P, u)
        return self.r
