"""The end of a contact within a sample or two: a second, sequential test on the observer's drive,
and the chi-square detector told that the residual is decaying.

Why. After a release at t_r the residual decays as r_k = A^(k−k_r) r_{k_r} (the exact observer,
A = exp(−KΔt) per row), so a detector waiting for ‖r‖ to fall under its threshold (one false
alarm per hour) keeps the flag up for ln(‖r‖_w/√h)/K: 36–54 ms after a 7 N poke.

The test. The drive x_k = (r_k − A r_{k−1})/b = d_{k−1} is the step mean of τ_ext plus sensor
noise (lag-zero S0, lag-one S1, long-run Ω: estimator.bounds.ResidualNoise). While a contact
holds, x_k ≈ μ_k = r_{k−1} (the residual tracks τ_ext); once released, x_k ≈ 0. The log-likelihood
ratio of "released" to "held" per step, in the long-run metric W = Ω⁻¹,

    ℓ_k = ½ μ_kᵀ W μ_k − μ_kᵀ W x_k          (mean −½D held, +½D released, D = μᵀWμ),

drives a CUSUM g_k = max(0, g_{k−1} + ℓ_k) from the contact's onset; a release is declared when
g_k > h_rel = ln(1/α), α the detector's false-alarm probability per sample: the increments are a
Gaussian walk with drift ∓D/2 and long-run variance D, whose excursions reach h with probability
≈ e^(−h) whatever D (a weak contact is not cut short more often than a strong one). A contact of
1 N on the paper leg has D ≈ 10³: the first released sample alone gives ℓ ≈ D/2 ≫ h.

After a release at sample k_r the chi-square test reads ρ_k = r_k − A^(k−k_r) r_{k_r}, the residual
minus its predicted free decay (the observer restarted at k_r, estimator.onset): a new contact
shows in ρ at once, the old one's tail does not. Cov ρ_k ⪯ R, so the false-alarm rate is the
stated one or lower. The anchor is dropped once its decay is below 10⁻⁶ of the noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_KERNEL = None
NEGLIGIBLE = 1e-6              # the anchor's whitened decay below which ρ = r


@dataclass
class ReleaseState:
    """What the test carries across chunks (plain numbers and arrays)."""

    in_contact: bool = False
    g: float = 0.0
    t_prev: float = float("nan")
    r_prev: np.ndarray | None = None
    v_prev: np.ndarray | None = None
    anchor_t: float = float("nan")
    anchor_r: np.ndarray | None = None      # None: no decay being subtracted
    anchor_w: float = 0.0                   # ‖L⁻¹ r_anchor‖ (for dropping it)


def _loop(t, r, K, Linv, W, idx, h, h_rel, st_f, st_prev, st_vprev, st_anchor, contact, stat,
          released):
    """The per-sample state machine (module doc); st_f = [in_contact, g, t_prev, has_prev,
    anchor_t, has_anchor, anchor_w], st_prev = r_{k−1}, st_vprev = the tested residual at k − 1
    (r minus a released contact's tail: μ), st_anchor = r_anchor (all updated in place)."""
    T, n = r.shape
    v = np.empty(n)
    x = np.empty(n)
    for k in range(T):
        L = Linv[idx[k]]
        Wk = W[idx[k]]
        has_prev = st_f[3] > 0.5
        if st_f[5] > 0.5:                              # subtract the decaying tail
            dt = t[k] - st_f[4]
            for i in range(n):
                v[i] = r[k, i] - np.exp(-K[i] * dt) * st_anchor[i]
            if np.exp(-K.min() * dt) * st_f[6] < NEGLIGIBLE:
                st_f[5] = 0.0
        else:
            for i in range(n):
                v[i] = r[k, i]
        s = 0.0
        for i in range(n):
            z = 0.0
            for j in range(i + 1):
                z += L[i, j] * v[j]
            s += z * z
        stat[k] = s
        raw = s > h
        released[k] = False
        if st_f[0] > 0.5:
            if not raw:
                st_f[0] = 0.0
                contact[k] = False
            else:
                ell = 0.0
                if has_prev:
                    dt = t[k] - st_f[2]
                    for i in range(n):
                        a = np.exp(-K[i] * dt)
                        x[i] = (r[k, i] - a * st_prev[i]) / (1.0 - a)
                    for i in range(n):
                        wm = 0.0
                        for j in range(n):
                            wm += Wk[i, j] * st_vprev[j]
                        ell += wm * (0.5 * st_vprev[i] - x[i])
                g = st_f[1] + ell
                st_f[1] = g if g > 0.0 else 0.0
                if st_f[1] > h_rel:                    # released: flag off, subtract the tail
                    st_f[0] = 0.0
                    st_f[1] = 0.0
                    contact[k] = False
                    released[k] = True
                    st_f[4] = t[k]
                    st_f[5] = 1.0
                    aw = 0.0
                    for i in range(n):
                        st_anchor[i] = r[k, i]
                        z = 0.0
                        for j in range(i + 1):
                            z += L[i, j] * r[k, j]
                        aw += z * z
                    st_f[6] = np.sqrt(aw)
                else:
                    contact[k] = True
        else:
            contact[k] = raw
            if raw:
                st_f[0] = 1.0
                st_f[1] = 0.0
        for i in range(n):
            st_prev[i] = r[k, i]
            st_vprev[i] = v[i]
        st_f[2] = t[k]
        st_f[3] = 1.0


def _kernel():
    global _KERNEL
    if _KERNEL is None:
        from estimator import compiled

        try:
            if not compiled.available():
                raise ImportError
            from numba import njit

            _KERNEL = njit(cache=True, nogil=True, error_model="numpy")(_loop)
        except ImportError:
            _KERNEL = False
    if _KERNEL is False or not _kernels_enabled():
        return _loop
    return _KERNEL


def _kernels_enabled() -> bool:
    from estimator import compiled

    return compiled.ENABLED


def detect(t, r, K, Linv, W, idx, h: float, h_rel: float, state: ReleaseState):
    """(contact (T,) bool, statistic (T,), released (T,) bool) for consecutive samples: the
    chi-square test (threshold h) on r, or on r minus a released contact's decaying tail, with the
    release CUSUM (threshold h_rel) ending contacts (module doc). Linv, W: (B, n, n) whitening and
    long-run weights, sample k uses block idx[k]; ``state`` is updated."""
    t = np.ascontiguousarray(t, float)
    r = np.ascontiguousarray(r, float)
    T, n = r.shape
    contact = np.zeros(T, np.bool_)
    stat = np.zeros(T)
    released = np.zeros(T, np.bool_)
    st_f = np.array([state.in_contact, state.g, state.t_prev, state.r_prev is not None,
                     state.anchor_t, state.anchor_r is not None, state.anchor_w], float)
    st_prev = np.zeros(n) if state.r_prev is None else np.array(state.r_prev, float)
    st_vprev = np.zeros(n) if state.v_prev is None else np.array(state.v_prev, float)
    st_anchor = np.zeros(n) if state.anchor_r is None else np.array(state.anchor_r, float)
    if T:
        _kernel()(t, r, np.asarray(K, float), np.ascontiguousarray(Linv, float),
                  np.ascontiguousarray(W, float), np.ascontiguousarray(idx, np.int64), float(h),
                  float(h_rel), st_f, st_prev, st_vprev, st_anchor, contact, stat, released)
    state.in_contact, state.g, state.t_prev = bool(st_f[0]), float(st_f[1]), float(st_f[2])
    state.r_prev = st_prev if st_f[3] else None
    state.v_prev = st_vprev if st_f[3] else None
    state.anchor_t, state.anchor_w = float(st_f[4]), float(st_f[6])
    state.anchor_r = st_anchor if st_f[5] else None
    return contact, stat, released
