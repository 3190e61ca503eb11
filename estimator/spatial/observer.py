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
from userio.errors import InputError


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


class ObserverRun(obs.ObserverRun):
    """The offline observer over chunks on a UrdfModel (estimator.observer.ObserverRun):
    ``feed(t, q, v, tau_meas)`` → dict with r (T, nv) of the rows finalized now."""

    def __init__(self, model, gain_per_s, dt_s: float, method: str = "exact", timing=None):
        super().__init__(model.momentum_terms, gains(model, gain_per_s), dt_s, method, timing)
        self.model = model

    def feed(self, t, q, v, tau, final: bool = False):
        out = super().feed(t, q, v, tau, final)
        if out is None:
            return None
        return {"t": out["t"], "q": out["q"], "v": out["dq"], "tau": out["tau"], "r": out["rT"].T}


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
