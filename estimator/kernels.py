"""Per-sample loops compiled with numba: the observer's momentum terms and the dynamic
localization, fused (one pass over the samples, no temporaries). Same equations as the numpy
forms they replace (``observer.chain_terms``, ``localization.localize_dynamic``), which stay as
the references they are tested against; ``available()`` is False without numba (the numpy forms
are then used). Each sample is computed on its own, so a batch's results do not depend on how a
log is cut into chunks.
"""

from __future__ import annotations

import math

import numpy as np

_KERNELS = None
ENABLED = True                  # False: the numpy forms everywhere (tests compare the two)


def available() -> bool:
    return ENABLED and _load() is not None


def warm() -> bool:
    """Compile the loops once on a two-sample paper leg (numba writes them to its cache beside
    this file, so the first estimate does not pay the compile); False without numba."""
    if not available():
        return False
    from estimator.localization import weight_blocks
    from estimator.observer import full_robot
    from estimator.robot import paper_leg

    robot = full_robot(paper_leg())
    q = np.zeros((2, 5))
    PT, uT = momentum_terms_T(robot, q, q, q)
    from estimator import model_kernels

    model_kernels.warm(robot)
    for q_now in (q, None):         # the estimator passes the current posture; localize alone not
        localize_dynamic(robot, q, uT.T + 1.0, weight_blocks(5, 2), q_now, min_force_N=0.05,
                         max_condition=20.0, ambiguity_tol=1e-3, position_tol_m=0.005,
                         bound_tol=0.05)
    for base in (3, 0):             # the log reader's loops: floating and fixed base
        split_rows(np.zeros((1 + 2 * (base + 2) + 5, 3)).T, base, 2)          # column-major blocks
        split_rows(np.zeros((1 + 2 * (base + 2) + 5, 4)).T[1:], base, 2)      # and slices of them
        valid, t, *_, rows = split_rows(np.zeros((3, 1 + 2 * (base + 2) + 5)), base, 2)
        check_steps(t + np.arange(3), rows, None, 1.0, 0.01, True)
        check_steps(t + np.arange(3), rows, (-1.0, -1), 1.0, 0.01, True)
    from estimator.outframe import _empty_part
    format_rows(_empty_part())
    first_order(np.ones(2), np.ones(2), np.zeros((2, 2)), np.zeros((2, 3)), 0, 2)
    plausibility_rows(t, np.zeros((3, 5)), np.zeros((3, 5)), 0, 2, 6.3, None, np.zeros(3))
    plausibility_rows(t, np.zeros((3, 5)), np.zeros((3, 5)), 3, 2, 6.3, (-1.0, np.zeros(2), np.zeros(2)),
                      np.zeros(3))
    return True


def _load():
    global _KERNELS
    if _KERNELS is None:
        try:
            _KERNELS = _compile()
        except ImportError:
            _KERNELS = False
    return _KERNELS or None


def _terms_py(q, dq, tau, m, l, rc, rp, Irot, g, Gz, msuf, PT, uT):
    """P = M q̇ and u = τ + Cᵀq̇ − G (observer._FastTerms) for every sample, link-major."""
    T, n = q.shape
    N = n - 3
    cx = np.empty(N)
    cz = np.empty(N)
    vx = np.empty(N)
    vz = np.empty(N)
    ox = np.empty(N)
    oz = np.empty(N)
    vox = np.empty(N)
    voz = np.empty(N)
    for k in range(T):
        phi = q[k, 2]
        dphi = dq[k, 2]
        jx = 0.0
        jz = 0.0
        vjx = dq[k, 0]
        vjz = dq[k, 1]
        for i in range(N):
            phi += q[k, 3 + i]
            dphi += dq[k, 3 + i]
            s = math.sin(phi)
            c = math.cos(phi)
            ox[i] = jx
            oz[i] = jz
            vox[i] = vjx
            voz[i] = vjz
            cx[i] = jx + rc[i] * s + rp[i] * c
            cz[i] = jz - rc[i] * c + rp[i] * s
            vx[i] = vjx + dphi * (rc[i] * c - rp[i] * s)
            vz[i] = vjz + dphi * (rc[i] * s + rp[i] * c)
            jx = jx + l[i] * s
            jz = jz - l[i] * c
            vjx = vjx + l[i] * dphi * c
            vjz = vjz + l[i] * dphi * s
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += Irot[i, j] * dq[k, j]
            PT[i, k] = acc
            uT[i, k] = tau[k, i]
        uT[1, k] -= Gz
        A = 0.0
        Bx = 0.0
        Bz = 0.0
        Gs = 0.0
        for i in range(N - 1, -1, -1):
            A += m[i] * (cx[i] * vz[i] - cz[i] * vx[i])
            Bx += m[i] * vx[i]
            Bz += m[i] * vz[i]
            Gs += m[i] * cx[i]
            Pang = A - (ox[i] * Bz - oz[i] * Bx)
            Cang = -(vox[i] * Bz - voz[i] * Bx)
            Gang = g * (Gs - ox[i] * msuf[i])
            if i == 0:
                PT[2, k] += Pang
                uT[2, k] += Cang - Gang
            PT[3 + i, k] += Pang
            uT[3 + i, k] += Cang - Gang
        PT[0, k] += Bx
        PT[1, k] += Bz

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


def _split_rows_py(values, base, n, valid, t_o, q_o, dq_o, tau_o, w_o, rows_o):
    """One pass over a block of a log (rows, columns in ``log.log_columns`` order): valid[i] =
    every field of row i finite; the valid rows' fields copied, in order, into t, q and q̇
    (floating coordinates: a fixed base's three columns zero), τ, wrench and their row
    indices. Returns the number of valid rows."""
    T, C = values.shape
    pad = 3 - base
    i0 = 1 + 2 * (base + n)
    k = 0
    for i in range(T):
        ok = True
        for j in range(C):
            if not math.isfinite(values[i, j]):
                ok = False
                break
        valid[i] = ok
        if not ok:
            continue
        t_o[k] = values[i, 0]
        for j in range(pad):
            q_o[k, j] = 0.0
            dq_o[k, j] = 0.0
        for j in range(base + n):
            q_o[k, pad + j] = values[i, 1 + j]
            dq_o[k, pad + j] = values[i, 1 + base + n + j]
        for j in range(n):
            tau_o[k, j] = values[i, i0 + j]
        for j in range(3):
            w_o[k, j] = values[i, i0 + n + j]
        rows_o[k] = i
        k += 1
    return k


def _check_steps_py(t, rows, has_last, last_t, last_row, dt, max_jitter, regular):
    """The time steps of tt = [last_t if has_last] + t (file rows rr likewise): (1, k) if step k
    (tt[k] → tt[k+1]) does not increase (the first such); else, if ``regular``, (2, k) for the
    first step that is not a whole number of periods dt (±max_jitter) or whose number of periods
    is not the rows it spans; else (0, −1). The tests of ``log.LogReader._validate``."""
    off0 = 1 if has_last else 0
    m = len(t) + off0 - 1
    for k in range(m):
        a = last_t if (has_last and k == 0) else t[k - off0]
        if t[k + 1 - off0] - a <= 0:
            return 1, k
    if regular:
        for k in range(m):
            a = last_t if (has_last and k == 0) else t[k - off0]
            ra = last_row if (has_last and k == 0) else rows[k - off0]
            ratio = (t[k + 1 - off0] - a) / dt
            r = np.rint(ratio)
            if abs(ratio - max(r, 1.0)) > max_jitter or r != rows[k + 1 - off0] - ra:
                return 2, k
    return 0, -1


def _plausibility_py(t, q, dq, base, n, max_angle, has_last, t0, q0, d0, sums):
    """Checker.rows in one pass: the first (k, j) with |q_j| > max_angle (joint angles) or
    (−1, −1); else the sums Σ fd·mid, Σ mid·mid, Σ fd·fd over the steps of [last] + rows
    (fd = Δq/Δt, mid = ½(q̇_k + q̇_{k+1}), coordinates from ``base`` on) added to ``sums``."""
    T, C = q.shape
    for k in range(T):
        for j in range(n):
            if abs(q[k, 3 + j]) > max_angle:
                return k, j
    s0, s1, s2 = 0.0, 0.0, 0.0
    for k in range(-1 if has_last else 0, T - 1):
        ta = t0 if k < 0 else t[k]
        h = t[k + 1] - ta
        for j in range(base, C):
            qa = q0[j - base] if k < 0 else q[k, j]
            da = d0[j - base] if k < 0 else dq[k, j]
            fd = (q[k + 1, j] - qa) / h
            mid = (dq[k + 1, j] + da) * 0.5
            s0 += fd * mid
            s1 += mid * mid
            s2 += fd * fd
    sums[0] += s0
    sums[1] += s1
    sums[2] += s2
    return -1, -1


def plausibility_rows(t, q, dq, base, n, max_angle, last, sums):
    """``_plausibility_py`` compiled; ``last``: (t, q, q̇) of the previous row (coordinates from
    ``base`` on) or None. → (k, j) of the first joint angle beyond ``max_angle``, or (−1, −1)."""
    k = _load()
    has = last is not None
    q0 = np.ascontiguousarray(last[1], float).ravel() if has else np.zeros(q.shape[1] - base)
    d0 = np.ascontiguousarray(last[2], float).ravel() if has else np.zeros(q.shape[1] - base)
    return k["plaus"](np.ascontiguousarray(t, float), np.ascontiguousarray(q, float),
                      np.ascontiguousarray(dq, float), int(base), int(n), float(max_angle), has,
                      float(last[0]) if has else 0.0, q0, d0, sums)


def split_rows(values, base, n):
    """(valid, t, q, q̇, τ, wrench, rows) of a log block with the compiled ``_split_rows_py``."""
    k = _load()
    values = np.asarray(values, float)        # any layout: row- or column-major, or a slice
    T = len(values)
    valid = np.empty(T, np.bool_)
    t, rows = np.empty(T), np.empty(T, np.int64)
    q, dq = np.empty((T, n + 3)), np.empty((T, n + 3))
    tau, w = np.empty((T, n)), np.empty((T, 3))
    m = k["split"](values, base, n, valid, t, q, dq, tau, w, rows)
    if m < T:
        t, q, dq, tau, w, rows = t[:m], q[:m], dq[:m], tau[:m], w[:m], rows[:m]
    return valid, t, q, dq, tau, w, rows


def check_steps(t, rows, last, dt, max_jitter, regular):
    """``_check_steps_py`` compiled; ``last``: (t, row) of the previous valid row or None."""
    k = _load()
    has = last is not None
    return k["steps"](t, rows, has, float(last[0]) if has else 0.0, int(last[1]) if has else 0,
                      float(dt), float(max_jitter), bool(regular))


def _first_order_py(a, b, drive, out, start, stop):
    """out[j, k+1] = a_j out[j, k] + b_j drive[j, k] for k = start … stop−1 (the observer's
    recursion, in the order ``scipy.signal.lfilter`` evaluates it: b·x first, then + a·y)."""
    for j in range(drive.shape[0]):
        y = out[j, start]
        for k in range(start, stop):
            y = b[j] * drive[j, k] + a[j] * y
            out[j, k + 1] = y


def first_order(a, b, drive, out, start: int, stop: int) -> bool:
    """Run ``_first_order_py`` compiled in place on ``out``; False without numba."""
    k = _load() if ENABLED else None
    if k is None:
        return False
    k["filter"](a, b, drive, out, start, stop)
    return True


_POW10_INT = np.array([10 ** i for i in range(19)], dtype=np.int64)
_POW10_FLOAT = 10.0 ** np.arange(23)          # exact powers of ten (outframe.round_significant)


def _put_uint_py(buf, pos, v, width):
    """Write v ≥ 0 in decimal at buf[pos:], at least ``width`` digits (leading zeros); → new pos."""
    n = 1
    while n < 19 and v >= _POW10_INT[n]:
        n += 1
    if n < width:
        n = width
    end = pos + n
    while n > 0:
        end_i = pos + n - 1
        buf[end_i] = 48 + v % 10
        v //= 10
        n -= 1
    return end


def _put_float_py(buf, pos, x, digits):
    """x rounded to ``digits`` significant digits (outframe.round_significant) and printed as
    pyarrow's CSV writer prints that double (its shortest decimal: plain for a decimal exponent
    in [−6, 10), else d.ddde±x; nan, inf, -inf, 0, -0); → new pos, or −1 for the few values
    round_significant leaves as they are (|x| < 1e−14 or ≥ 1e31 at 9 digits)."""
    if x != x:
        buf[pos], buf[pos + 1], buf[pos + 2] = 110, 97, 110            # nan
        return pos + 3
    if x < 0 or (x == 0 and math.copysign(1.0, x) < 0):
        buf[pos] = 45                                                   # -
        pos += 1
    a = abs(x)
    if a == math.inf:
        buf[pos], buf[pos + 1], buf[pos + 2] = 105, 110, 102            # inf
        return pos + 3
    if a == 0:
        buf[pos] = 48
        return pos + 1
    _, e2 = math.frexp(a)
    k = (digits - 1) - int(math.floor((e2 - 1) * 0.30102999566398120))
    if k > 22 or k < -22:
        return -1
    if k >= 0:
        m = np.int64(np.rint(a * _POW10_FLOAT[k]))
    else:
        m = np.int64(np.rint(a / _POW10_FLOAT[-k]))
    # the double nearest m·10^−k prints as m·10^−k without its trailing zeros
    while m % 10 == 0:
        m //= 10
        k -= 1
    nd = 1
    while nd < 19 and m >= _POW10_INT[nd]:
        nd += 1
    e = nd - 1 - k                                                      # decimal exponent
    if -6 <= e < 10:
        if e < 0:
            buf[pos], buf[pos + 1] = 48, 46                             # 0.
            pos += 2
            for _ in range(-e - 1):
                buf[pos] = 48
                pos += 1
            return _put_uint(buf, pos, m, nd)
        if nd <= e + 1:
            pos = _put_uint(buf, pos, m, nd)
            for _ in range(e + 1 - nd):
                buf[pos] = 48
                pos += 1
            return pos
        low = nd - e - 1
        pos = _put_uint(buf, pos, m // _POW10_INT[low], 1)
        buf[pos] = 46
        return _put_uint(buf, pos + 1, m % _POW10_INT[low], low)
    pos = _put_uint(buf, pos, m // _POW10_INT[nd - 1], 1)
    if nd > 1:
        buf[pos] = 46
        pos = _put_uint(buf, pos + 1, m % _POW10_INT[nd - 1], nd - 1)
    buf[pos] = 101                                                      # e
    buf[pos + 1] = 43 if e > 0 else 45
    return _put_uint(buf, pos + 2, abs(e), 1)


def _format_rows_py(t, contact, link, alpha, Fx, Fz, px, pz, rnorm, digits, buf):
    """The rows ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm`` (outframe.COLUMNS) as CSV text in buf;
    → bytes written, or −1 if a value needs pyarrow's writer (``_put_float_py``)."""
    pos = 0
    for i in range(len(t)):
        pos = _put_float(buf, pos, t[i], digits)
        if pos < 0:
            return -1
        buf[pos] = 44
        buf[pos + 1] = 49 if contact[i] else 48
        buf[pos + 2] = 44
        pos += 3
        v = link[i]
        if v < 0:
            buf[pos] = 45
            pos += 1
            v = -v
        pos = _put_uint(buf, pos, v, 1)
        for x in (alpha[i], Fx[i], Fz[i], px[i], pz[i], rnorm[i]):
            buf[pos] = 44
            pos = _put_float(buf, pos + 1, x, digits)
            if pos < 0:
                return -1
        buf[pos] = 10
        pos += 1
    return pos


def format_rows(part, digits: int = 9) -> bytes | None:
    """The CSV rows of an estimate part (no header) as pyarrow's writer prints the part rounded
    by ``outframe.round_significant``, or None if a value needs pyarrow's writer."""
    k = _load()
    T = len(part.t)
    buf = np.empty(T * (7 * 24 + 30), np.uint8)
    f = [np.ascontiguousarray(a, float) for a in (part.t, part.alpha, part.Fx, part.Fz, part.px,
                                                  part.pz, part.rnorm)]
    n = k["rows"](f[0], np.ascontiguousarray(part.contact, np.bool_),
                  np.ascontiguousarray(part.link, np.int64), *f[1:], int(digits), buf)
    return None if n < 0 else buf[:n].tobytes()


_fit = None                     # the compiled _fit_py, a global for _localize_py
_put_uint = None                # the compiled _put_uint_py and _put_float_py, globals for the rows
_put_float = None


def _compile():
    """Compile the loops (numba, cached beside this file); ImportError without numba."""
    global _fit, _put_uint, _put_float
    from numba import njit

    jit = njit(cache=True, nogil=True, error_model="numpy")
    _fit = jit(_fit_py)
    _put_uint = jit(_put_uint_py)
    _put_float = jit(_put_float_py)
    return {"terms": jit(_terms_py), "localize": jit(_localize_py), "split": jit(_split_rows_py),
            "steps": jit(_check_steps_py), "rows": jit(_format_rows_py),
            "plaus": jit(_plausibility_py), "filter": jit(_first_order_py)}




def momentum_terms_T(robot, q, dq, tau):
    """(P, u) link-major (n, T) with the compiled loop (robot: floating coordinates)."""
    from estimator.observer import _irot

    k = _load()
    q = np.ascontiguousarray(q, float)
    dq = np.ascontiguousarray(dq, float)
    tau = np.ascontiguousarray(tau, float)
    T, n = q.shape
    m = np.asarray(robot.masses_kg, float)
    g = float(robot.gravity_m_per_s2)
    PT = np.empty((n, T))
    uT = np.empty((n, T))
    msuf = np.cumsum(m[::-1])[::-1].copy()
    k["terms"](q, dq, tau, m, np.asarray(robot.lengths_m, float), np.asarray(robot.com_m, float),
               np.asarray(robot.com_perp_m, float), _irot(robot), g,
               g * (float(robot.base_mass_kg) + float(m.sum())), msuf, PT, uT)
    return PT, uT


def localize_dynamic(robot, q, r, weight, q_now=None, *, min_force_N, max_condition, ambiguity_tol,
                     position_tol_m, bound_tol):
    """Arrays (link, α, F, p, condition, reason, cost) of localization.localize_dynamic (no
    expected contacts) with the compiled loop; p at ``q_now`` if given. ``weight``: (W (B, n, n),
    index (T,)), sample t weighted by W[index[t]] (localization.weight_blocks)."""
    k = _load()
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
