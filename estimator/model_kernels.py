"""Compiled loops of the inertial-parameter model (numba): the planar chain's momentum regressor
(estimator.inertial) and the detector's statistic with the model-error term (estimator.model_error),
alone or fused with the regressor. The numpy forms in those modules are their references; without
numba (or with ``estimator.compiled.ENABLED`` False) every entry point returns False / the caller
falls back. Loaded lazily, cached beside this file (estimator.compiled; estimator.warmup compiles
them at install).
"""

from __future__ import annotations

import math

import numpy as np

from estimator import compiled

_KERNELS = None
_regressor = None               # compiled _regressor_py and _model_chi2_py: globals for the fused
_mchi2 = None                   # loop _planar_model_chi2_py


def _load():
    global _KERNELS, _regressor, _mchi2
    if not compiled.available():
        return None
    if _KERNELS is None:
        from numba import njit

        jit = njit(cache=True, nogil=True, error_model="numpy")
        _regressor = jit(_regressor_py)
        # reassociation and fused multiply-add let LLVM vectorize the short dot products; NaN/inf
        # semantics kept (the not-positive-definite check must survive)
        _mchi2 = njit(cache=True, nogil=True, error_model="numpy",
                      fastmath={"reassoc", "contract", "arcp"})(_model_chi2_py)
        _KERNELS = {"regressor": _regressor, "modelchi2": _mchi2,
                    "planarmodel": jit(_planar_model_chi2_py)}
    return _KERNELS


def available() -> bool:
    return _load() is not None


def _regressor_py(q, dq, l, g, YP, Yu):
    """The momentum regressor (estimator.inertial.regressor_numpy) per sample: YP, Yu (T, n, n_θ),
    zero on entry."""
    T, n = q.shape
    N = n - 3
    px = np.empty(N + 1)
    pz = np.empty(N + 1)
    vx = np.empty(N + 1)
    vz = np.empty(N + 1)
    ex = np.empty(N)
    nx = np.empty(N)
    nz = np.empty(N)
    w = np.empty(N)
    Lx = np.empty(4)
    Lz = np.empty(4)
    H = np.empty(4)
    for k in range(T):
        phi = q[k, 2]
        dphi = dq[k, 2]
        px[0] = 0.0
        pz[0] = 0.0
        vx[0] = dq[k, 0]
        vz[0] = dq[k, 1]
        for i in range(N):
            phi += q[k, 3 + i]
            dphi += dq[k, 3 + i]
            s = math.sin(phi)
            c = math.cos(phi)
            ex[i] = s
            nx[i] = c
            nz[i] = s
            w[i] = dphi
            px[i + 1] = px[i] + l[i] * s
            pz[i + 1] = pz[i] - l[i] * c
            vx[i + 1] = vx[i] + l[i] * dphi * c
            vz[i + 1] = vz[i] + l[i] * dphi * s
        YP[k, 0, 0] = dq[k, 0]
        YP[k, 1, 0] = dq[k, 1]
        YP[k, 2, 1] = dq[k, 2]
        Yu[k, 1, 0] = -g
        for i in range(N):
            c0 = 2 + 4 * i
            ez = -nx[i]                        # e_z = −cos φ
            Lx[0] = vx[i]
            Lz[0] = vz[i]
            Lx[1] = w[i] * nx[i]
            Lz[1] = w[i] * nz[i]
            Lx[2] = -w[i] * ex[i]
            Lz[2] = -w[i] * ez
            Lx[3] = 0.0
            Lz[3] = 0.0
            H[0] = 0.0
            H[1] = ex[i] * vz[i] - ez * vx[i]
            H[2] = nx[i] * vz[i] - nz[i] * vx[i]
            H[3] = w[i]
            for j in range(4):
                YP[k, 0, c0 + j] = Lx[j]
                YP[k, 1, c0 + j] = Lz[j]
            Yu[k, 1, c0] = -g
            for a in range(i + 2):
                o = a - 1 if a > 0 else 0
                dx = px[i] - px[o]
                dz = pz[i] - pz[o]
                for j in range(4):
                    YP[k, 2 + a, c0 + j] = H[j] + dx * Lz[j] - dz * Lx[j]
                    Yu[k, 2 + a, c0 + j] = -(vx[o] * Lz[j] - vz[o] * Lx[j])
                Yu[k, 2 + a, c0] -= g * dx
                Yu[k, 2 + a, c0 + 1] -= g * ex[i]
                Yu[k, 2 + a, c0 + 2] -= g * nx[i]


def momentum_regressor(robot, q, v):
    """(Y_P, Y_u) (T, n, n_θ) of estimator.inertial with the compiled ``_regressor_py``."""
    k = _load()
    q = np.ascontiguousarray(q, float)
    v = np.ascontiguousarray(v, float)
    T, n = q.shape
    YP = np.zeros((T, n, 2 + 4 * (n - 3)))
    Yu = np.zeros_like(YP)
    k["regressor"](q, v, np.asarray(robot.lengths_m, float), float(robot.gravity_m_per_s2), YP, Yu)
    return YP, Yu


def _model_chi2_py(YP, Yu, act_ptr, act, S, ncol, a, b, K, t, dt, exact, has_prev, t_prev, PP, PU,
                   PF, rT, Rn, blk, G, stat):
    """The detector's statistic with the model-error term (estimator.model_error), per sample k:

        D_k = (Y_P,k − Y_P,k−1)/Δt − ½ (Y_u,k−1 + Y_u,k)      (explicit: − Y_u,k−1)
        Φ_k = a ∘ Φ_k−1 + b ∘ D_k      (per row; a step ≠ Δt: its own a, b; Φ_0 = 0)
        G_k = Φ_k S,   s_k = r_kᵀ (Rn[blk_k] + G_k G_kᵀ)⁻¹ r_k   (Cholesky in place; NaN if not PD)

    Only the regressor's structurally nonzero entries are carried (row i's columns
    act[act_ptr[i]:act_ptr[i+1]]); S is (n_θ, r), row j nonzero in its first ncol[j] columns (a
    Cholesky factor: j + 1). PP, PU, PF: the previous sample's Y_P, Y_u, Φ
    (n, n_θ; zeros before the first sample), updated in place at the end; G (T, n, r) and stat
    (T,) out."""
    T, n, k = YP.shape
    r = S.shape[1]
    L = np.empty((n, n))
    z = np.empty(n)
    g = np.empty((n, r))
    for s in range(T):
        inv = 1.0 / dt
        regular = True
        h = dt
        if s > 0 or has_prev:
            h = t[s] - (t_prev if s == 0 else t[s - 1])
            regular = abs(h - dt) <= 0.01 * dt
            if not regular:
                inv = 1.0 / h
        for i in range(n):
            if s == 0 and not has_prev:          # Φ_0 = 0 (the observer's r_0 = 0)
                ai = 0.0
                bi = 0.0
            elif regular:
                ai = a[i]
                bi = b[i]
            elif exact:
                ai = math.exp(-K[i] * h)
                bi = -math.expm1(-K[i] * h)
            else:
                ai = 1.0 - K[i] * h
                bi = K[i] * h
            c1 = bi * inv
            c2 = 0.5 * bi if exact else bi
            c3 = 0.5 * bi if exact else 0.0
            for c in range(r):
                g[i, c] = 0.0
            for p in range(act_ptr[i], act_ptr[i + 1]):
                j = act[p]
                if s > 0:                        # the previous sample: in the block, else state
                    pp = YP[s - 1, i, j]
                    pu = Yu[s - 1, i, j]
                else:
                    pp = PP[i, j]
                    pu = PU[i, j]
                f = c1 * (YP[s, i, j] - pp) - c2 * pu - c3 * Yu[s, i, j] + ai * PF[i, j]
                PF[i, j] = f
                for c in range(ncol[j]):
                    g[i, c] += f * S[j, c]
        B = blk[s]
        for i in range(n):
            for c in range(r):
                G[s, i, c] = g[i, c]
            for j in range(i + 1):
                acc = Rn[B, i, j]
                for c in range(r):
                    acc += g[i, c] * g[j, c]
                L[i, j] = acc
        ok = True
        for j in range(n):
            d = L[j, j]
            for m in range(j):
                d -= L[j, m] * L[j, m]
            if not d > 0.0:
                ok = False
                break
            d = math.sqrt(d)
            L[j, j] = d
            di = 1.0 / d
            for i in range(j + 1, n):
                v = L[i, j]
                for m in range(j):
                    v -= L[i, m] * L[j, m]
                L[i, j] = v * di
        if not ok:
            stat[s] = math.nan
            continue
        ss = 0.0
        for i in range(n):
            v = rT[i, s]
            for m in range(i):
                v -= L[i, m] * z[m]
            z[i] = v / L[i, i]
            ss += z[i] * z[i]
        stat[s] = ss
    if T > 0:
        for i in range(n):
            for j in range(k):
                PP[i, j] = YP[T - 1, i, j]
                PU[i, j] = Yu[T - 1, i, j]


FUSED_BLOCK = 64                # samples per regressor block in the fused loop (stays in L1/L2)


def _planar_model_chi2_py(q, dq, l, g, bufP, bufU, act_ptr, act, S, ncol, a, b, K, t, dt, exact,
                          has_prev, t_prev, PP, PU, PF, rT, Rn, blk, G, stat):
    """``_model_chi2_py`` on the planar chain's regressor (``_regressor_py``) computed block by
    block into the small buffers bufP, bufU (FUSED_BLOCK, n, n_θ): the regressor never leaves the
    cache. The buffers are zero outside the entries the regressor writes, every sample the same."""
    T = q.shape[0]
    for s0 in range(0, T, FUSED_BLOCK):
        s1 = min(T, s0 + FUSED_BLOCK)
        m = s1 - s0
        _regressor(q[s0:s1], dq[s0:s1], l, g, bufP[:m], bufU[:m])
        _mchi2(bufP[:m], bufU[:m], act_ptr, act, S, ncol, a, b, K, t[s0:s1], dt, exact,
               has_prev or s0 > 0, t_prev if s0 == 0 else t[s0 - 1], PP, PU, PF, rT[:, s0:s1], Rn,
               blk[s0:s1], G[s0:s1], stat[s0:s1])


def planar_model_chi2(robot, q, dq, bufs, pattern, a, b, K, t, dt, exact, has_prev, t_prev, PP, PU,
                      PF, rT, Rn, blk, G, stat) -> bool:
    """The fused loop for a planar Robot (``bufs``: two zeroed (FUSED_BLOCK, n, n_θ) arrays kept by
    the caller); False without numba."""
    k = _load()
    if k is None:
        return False
    k["planarmodel"](np.ascontiguousarray(q, float), np.ascontiguousarray(dq, float),
                     np.asarray(robot.lengths_m, float), float(robot.gravity_m_per_s2), *bufs,
                     *pattern, a, b, K, t, float(dt), bool(exact), bool(has_prev), float(t_prev),
                     PP, PU, PF, rT, Rn, blk, G, stat)
    return True


def model_chi2(YP, Yu, pattern, a, b, K, t, dt, exact, has_prev, t_prev, PP, PU, PF, rT, Rn, blk,
               G, stat) -> bool:
    """``_model_chi2_py`` compiled; ``pattern``: (act_ptr, act, S, ncol) of estimator.model_error.ModelTerm
    (state arrays PP, PU, PF updated in place); False without numba."""
    k = _load()
    if k is None:
        return False
    k["modelchi2"](YP, Yu, *pattern, a, b, K, t, float(dt), bool(exact), bool(has_prev),
                   float(t_prev), PP, PU, PF, rT, Rn, blk, G, stat)
    return True
