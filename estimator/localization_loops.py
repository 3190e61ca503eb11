"""The per-sample solve of ``localization.localize_dynamic`` (no expected contacts) as one loop
compiled with numba, fused: every link's weighted least-squares fit, the winner, its flags and its
point, in one pass over the samples without temporaries. Same equations as the numpy form in
estimator.localization, which stays as the reference it is tested against (equal to rounding);
without numba (``compiled.available()`` False) that form is used. Each sample is computed on its
own, so a batch's results do not depend on how a log is cut into chunks.
"""

from __future__ import annotations

import math

import numpy as np

from estimator import compiled


def _fit_py(r, W, jx, jz, c, N, H, WH, out):
    """Link c (1-based): weighted LS of (F, μ), min (r − H x)ᵀ W (r − H x) (W the inverse residual
    covariance), α clipped to [0, 1] and F re-fitted there (localization._fit_link). H, WH: (n, 3)
    scratch; out ← α_free, α, Fx, Fz, cost."""
    n = N + 3
    for i in range(n):
        H[i, 0] = 0.0
        H[i, 1] = 0.0
        H[i, 2] = 0.0
    H[0, 0] = 1.0
    H[1, 1] = 1.0
    for m in range(2, 3 + c):
        o = m - 3 if m > 3 else 0
        H[m, 0] = -(jz[c - 1] - jz[o])
        H[m, 1] = jx[c - 1] - jx[o]
        H[m, 2] = 1.0
    for i in range(n):
        for k in range(3):
            acc = 0.0
            for j in range(n):
                acc += W[i, j] * H[j, k]
            WH[i, k] = acc
    A11 = 0.0
    A12 = 0.0
    A13 = 0.0
    A22 = 0.0
    A23 = 0.0
    A33 = 0.0
    b1 = 0.0
    b2 = 0.0
    b3 = 0.0
    for i in range(n):
        A11 += H[i, 0] * WH[i, 0]
        A12 += H[i, 0] * WH[i, 1]
        A13 += H[i, 0] * WH[i, 2]
        A22 += H[i, 1] * WH[i, 1]
        A23 += H[i, 1] * WH[i, 2]
        A33 += H[i, 2] * WH[i, 2]
        b1 += WH[i, 0] * r[i]
        b2 += WH[i, 1] * r[i]
        b3 += WH[i, 2] * r[i]
    c11 = A22 * A33 - A23 * A23
    c12 = A13 * A23 - A12 * A33
    c13 = A12 * A23 - A13 * A22
    c22 = A11 * A33 - A13 * A13
    c23 = A12 * A13 - A11 * A23
    c33 = A11 * A22 - A12 * A12
    inv_det = 1.0 / (A11 * c11 + A12 * c12 + A13 * c13)
    Fx = (c11 * b1 + c12 * b2 + c13 * b3) * inv_det
    Fz = (c12 * b1 + c22 * b2 + c23 * b3) * inv_det
    mu = (c13 * b1 + c23 * b2 + c33 * b3) * inv_det
    dx = jx[c] - jx[c - 1]
    dz = jz[c] - jz[c - 1]
    den = dx * Fz - dz * Fx
    alpha_free = mu / den                          # error_model="numpy": ±inf or nan
    alpha = 0.5 if math.isnan(alpha_free) else min(max(alpha_free, 0.0), 1.0)
    if alpha != alpha_free:
        for m in range(2, 3 + c):                  # moment rows: (a_m + α Δ) × F
            H[m, 0] -= alpha * dz
            H[m, 1] += alpha * dx
        for i in range(n):
            for k in range(2):
                acc = 0.0
                for j in range(n):
                    acc += W[i, j] * H[j, k]
                WH[i, k] = acc
        B11 = 0.0
        B12 = 0.0
        B22 = 0.0
        d1 = 0.0
        d2 = 0.0
        for i in range(n):
            B11 += H[i, 0] * WH[i, 0]
            B12 += H[i, 0] * WH[i, 1]
            B22 += H[i, 1] * WH[i, 1]
            d1 += WH[i, 0] * r[i]
            d2 += WH[i, 1] * r[i]
        detB = B11 * B22 - B12 * B12
        Fx = (B22 * d1 - B12 * d2) / detB
        Fz = (B11 * d2 - B12 * d1) / detB
        mu = alpha * (dx * Fz - dz * Fx)
        for m in range(2, 3 + c):                  # back to the (F, μ) columns for the cost
            H[m, 0] += alpha * dz
            H[m, 1] -= alpha * dx
    cost2 = 0.0
    for i in range(n):
        ei = r[i] - (H[i, 0] * Fx + H[i, 1] * Fz + H[i, 2] * mu)
        for j in range(n):
            ej = r[j] - (H[j, 0] * Fx + H[j, 1] * Fz + H[j, 2] * mu)
            cost2 += ei * W[i, j] * ej
    out[0] = alpha_free
    out[1] = alpha
    out[2] = Fx
    out[3] = Fz
    out[4] = math.sqrt(max(cost2, 0.0))


def _localize_py(q, r, q_now, lengths, Wb, widx, min_force, max_condition, ambiguity_tol,
                 position_tol, bound_tol, link, alpha_o, force_o, point_o, cond_o, reason_o, cost_o):
    """localization.localize_dynamic without expected contacts, per sample (sample t weighted by
    Wb[widx[t]]); the point is reported at ``q_now`` (the current posture) from the body
    coordinate α."""
    T, n = q.shape
    N = n - 3
    jx = np.empty(N + 1)
    jz = np.empty(N + 1)
    H = np.empty((n, 3))
    WH = np.empty((n, 3))
    res = np.empty((N, 5))
    for t in range(T):
        phi = q[t, 2]
        jx[0] = 0.0
        jz[0] = 0.0
        for i in range(N):
            phi += q[t, 3 + i]
            jx[i + 1] = jx[i] + lengths[i] * math.sin(phi)
            jz[i + 1] = jz[i] - lengths[i] * math.cos(phi)
        W = Wb[widx[t]]
        best = 0
        for c in range(1, N + 1):
            _fit(r[t], W, jx, jz, c, N, H, WH, res[c - 1])
            if res[c - 1, 4] < res[best, 4]:
                best = c - 1
        second = -1
        for c in range(N):
            if c != best and (second < 0 or res[c, 4] < res[second, 4]):
                second = c
        af = res[best, 0]
        a = res[best, 1]
        Fx = res[best, 2]
        Fz = res[best, 3]
        cost = res[best, 4]
        sx = jx[best]
        sz = jz[best]
        dx = jx[best + 1] - sx
        dz = jz[best + 1] - sz
        px = (q[t, 0] + sx) + a * dx
        pz = (q[t, 1] + sz) + a * dz
        reason = 0
        if not (af >= -bound_tol and af <= 1 + bound_tol):
            reason = 5                                         # out_of_bounds
        if second >= 0 and res[second, 4] - cost < ambiguity_tol:
            a2 = res[second, 1]
            s2x = jx[second]
            s2z = jz[second]
            e2x = jx[second + 1]
            e2z = jz[second + 1]
            p2x = (q[t, 0] + s2x) + a2 * (e2x - s2x)
            p2z = (q[t, 1] + s2z) + a2 * (e2z - s2z)
            far = math.hypot(p2x - px, p2z - pz) > position_tol
            f2x = res[second, 2]
            f2z = res[second, 3]
            d2x = e2x - s2x
            d2z = e2z - s2z
            num = math.hypot(f2x, f2z) * math.hypot(d2x, d2z)
            cr2 = abs(d2x * f2z - d2z * f2x)
            cond2 = num / cr2
            if not (cond2 <= max_condition):
                far = True
            if reason == 0 and far:
                reason = 4                                     # ambiguous_link
        fn = math.hypot(Fx, Fz)
        cr = abs(dx * Fz - dz * Fx)
        num = fn * math.hypot(dx, dz)
        cond = num / cr
        if math.isnan(cond):
            cond = math.inf
        if reason == 0 and cond > max_condition:
            reason = 3                                         # parallel_to_link
        if reason != 6 and not (fn >= min_force):
            reason = 2                                         # small_force
        link[t] = best + 1
        force_o[t, 0] = Fx
        force_o[t, 1] = Fz
        cond_o[t] = cond
        reason_o[t] = reason
        cost_o[t] = cost
        if reason != 0:
            alpha_o[t] = math.nan
            point_o[t, 0] = math.nan
            point_o[t, 1] = math.nan
        else:
            alpha_o[t] = a
            if q_now is None:
                point_o[t, 0] = px
                point_o[t, 1] = pz
            else:                          # the same α at the current posture
                phi = q_now[t, 2]
                x0 = 0.0
                z0 = 0.0
                for i in range(best + 1):
                    phi += q_now[t, 3 + i]
                    x1 = x0 + lengths[i] * math.sin(phi)
                    z1 = z0 - lengths[i] * math.cos(phi)
                    if i < best:
                        x0 = x1
                        z0 = z1
                point_o[t, 0] = q_now[t, 0] + x0 + a * (x1 - x0)
                point_o[t, 1] = q_now[t, 1] + z0 + a * (z1 - z0)


def localize(robot, q, r, weight, q_now=None, *, min_force_N, max_condition, ambiguity_tol,
                     position_tol_m, bound_tol):
    """Arrays (link, α, F, p, condition, reason, cost) of localization.localize_dynamic (no
    expected contacts) with the compiled loop; p at ``q_now`` if given. ``weight``: (W (B, n, n),
    index (T,)), sample t weighted by W[index[t]] (localization.weight_blocks). Needs
    ``compiled.available()``."""
    k = _LOOPS.get()
    q = np.ascontiguousarray(q, float)
    r = np.ascontiguousarray(r, float)
    T = len(q)
    link = np.empty(T, np.int64)
    alpha = np.empty(T)
    force = np.empty((T, 2))
    point = np.empty((T, 2))
    cond = np.empty(T)
    reason = np.empty(T, np.int8)
    cost = np.empty(T)
    k["localize"](q, r, None if q_now is None else np.ascontiguousarray(q_now, float),
                  np.asarray(robot.lengths_m, float), np.ascontiguousarray(weight[0], float),
                  np.ascontiguousarray(weight[1], np.int64), float(min_force_N),
                  float(max_condition), float(ambiguity_tol), float(position_tol_m), float(bound_tol),
                  link, alpha, force, point, cond, reason, cost)
    return link, alpha, force, point, cond, reason, cost


_fit = None                     # the compiled _fit_py, a global for _localize_py


def _build():
    global _fit
    _fit = compiled.jit(_fit_py)
    return {"localize": compiled.jit(_localize_py)}


_LOOPS = compiled.Loops(_build)
