"""One contact point per episode: the maximum-likelihood α from all of an episode's samples, with
its covariance and the episode's Cramér–Rao bound, from sums that do not grow with the episode.

Data. The observer's drive x_k = (r_k − A r_{k−1})/b = d_{k−1}, the step mean of τ_ext over
[t_{k−1}, t_k] plus a moving average of order one of the sensor noise (estimator.bounds.
ResidualNoise: Cov x_k = S0, Cov(x_k, x_{k−1}) = S1, long-run Ω = S0 + S1 + S1ᵀ). It is the
residual seen through the inverse of the observer's filter (exact, no lag: the step's posture is
the mean of its end postures), and it skips what the observer's trapezoid misreads at a contact's
onset (estimator.onset): a run's first flagged sample s holds the onset step, so its episode
reads x_{s+1}, x_{s+2}, … only.

Model. x_k = J_k(α)ᵀG_k + ν_k, α fixed over the episode, the force G_k free per step.
Estimate. α̂ = argmin C(α), C(α) = Σ_k min_G ‖x_k − J_k(α)ᵀG‖²_W, W = Ω⁻¹ (per posture block):
a separable least squares (for fixed α, G_k = A⁻¹b with A = J W Jᵀ, b = J W x, and
C_k = xᵀWx − bᵀA⁻¹b exactly). C, dC/dα and d²C/dα² are summed per sample on a grid of α per link
(``GRID``); α̂ is the minimum of the quintic Hermite interpolant between the grid nodes.
Covariance. With g_k = Δ_k × G_k and u_k = W⊥ e_c (W⊥ = W − W Jᵀ A⁻¹ J W, e_c ones on the
moment rows θ, q_1…q_c) the score is Σ g_k u_kᵀ ν_k, so (sandwich, the MA(1) noise exactly)

    Var α̂ = V / I²,   I = Σ g_k² κ_k (κ = e_cᵀ W⊥ e_c),
    V = Σ g_k² u_kᵀ S0 u_k + 2 Σ g_k g_{k−1} u_kᵀ S1 u_{k−1};

g_k² is replaced by g_k² − Var ĝ_k (and the lag-one products likewise) so the plug-in of the
fitted forces does not overstate the information at low signal-to-noise. With W = Ω⁻¹, I is the
episode's Fisher information (estimator.bounds; the exact information of these L steps is
(L + 1)/L of it, tests/test_bounds.py), so the stated bound is 1/√I and V/I² → 1/I: the
estimator reaches it. The episodes themselves (runs, slides) are estimator.episode_tracker's.
"""

from __future__ import annotations

import math

import numpy as np

ALPHA_LO, ALPHA_HI = -0.05, 1.05
GRID = np.linspace(ALPHA_LO, ALPHA_HI, 12)      # 0.1 apart: quintic Hermite, α̂ within 1 % of σ (tests/test_episode.py)
KEYS = ("C", "dC", "I", "Ib", "V", "Vb", "V1", "Vb1", "d2C")   # V1, Vb1: the lag-one parts


def _solve2(A11, A12, A22, v1, v2):
    det = A11 * A22 - A12 * A12
    return (A22 * v1 - A12 * v2) / det, (A11 * v2 - A12 * v1) / det


def node_terms(x, jx, jz, c, W, S0, S1, prev, first):
    """Per-sample contributions on link c at every grid node, and the last sample's (g, u, z)
    for the lag-one terms of the next call.

    x (T, n) drives; jx, jz (N+1, T) joints at the step postures; W, S0, S1 (T, n, n); ``prev``:
    (g, u, z) of the sample before the first one ((G,), (G, n), (G, n)) or None; ``first`` (T,)
    bool: no lag-one term with the sample before. Returns dict of (T, G) arrays (KEYS) and prev.
    """
    T, n = x.shape
    G = GRID.size
    ec = np.zeros(n)
    ec[2:3 + c] = 1.0
    org = np.r_[0, 0:c]
    J0 = np.zeros((T, n, 2))                       # J0ᵀ: columns F_x, F_z at α = 0
    J0[:, 0, 0] = 1.0
    J0[:, 1, 1] = 1.0
    J0[:, 2:3 + c, 0] = -(jz[c - 1] - jz[org]).T
    J0[:, 2:3 + c, 1] = (jx[c - 1] - jx[org]).T
    dt_ = np.stack([-(jz[c] - jz[c - 1]), jx[c] - jx[c - 1]], -1)     # Δ̃ = (−Δ_z, Δ_x), (T, 2)
    WJ0 = W @ J0                                   # (T, n, 2)
    We = W @ ec                                    # (T, n)
    sc = We @ ec                                   # e_cᵀ W e_c
    A0 = np.swapaxes(J0, 1, 2) @ WJ0               # (T, 2, 2)
    Jwe = np.einsum("tni,tn->ti", J0, We)          # J0 W e_c  (A01 = Jwe ⊗ Δ̃)
    Wx = np.einsum("tij,tj->ti", W, x)
    xWx = np.einsum("ti,ti->t", x, Wx)
    b0 = np.einsum("tni,tn->ti", J0, Wx)
    ex = Wx @ ec                                   # e_cᵀ W x
    al = GRID[None, :]
    # A(α) = A0 + α (Jwe Δ̃ᵀ + Δ̃ Jweᵀ) + α² s_c Δ̃ Δ̃ᵀ; b(α) = b0 + α Δ̃ e_cᵀWx; m(α) = Jwe + α s_c Δ̃
    def quad(i, j):
        return (A0[:, i, j, None] + al * (Jwe[:, i, None] * dt_[:, j, None] + dt_[:, i, None] * Jwe[:, j, None])
                + al * al * (sc * dt_[:, i] * dt_[:, j])[:, None])
    A11, A12, A22 = quad(0, 0), quad(0, 1), quad(1, 1)
    b1 = b0[:, 0, None] + al * (dt_[:, 0] * ex)[:, None]
    b2 = b0[:, 1, None] + al * (dt_[:, 1] * ex)[:, None]
    G1, G2 = _solve2(A11, A12, A22, b1, b2)        # fitted forces (T, G)
    cost = xWx[:, None] - (b1 * G1 + b2 * G2)
    # dC/dα = −2 b'ᵀG + Gᵀ A' G, b' = Δ̃ e_cᵀWx, A' = Jwe Δ̃ᵀ + Δ̃ Jweᵀ + 2α s_c Δ̃Δ̃ᵀ
    g = dt_[:, 0, None] * G1 + dt_[:, 1, None] * G2                   # Δ × G
    jg = Jwe[:, 0, None] * G1 + Jwe[:, 1, None] * G2
    dcost = -2 * ex[:, None] * g + 2 * jg * g + 2 * al * sc[:, None] * g * g
    m1 = Jwe[:, 0, None] + al * (sc * dt_[:, 0])[:, None]
    m2 = Jwe[:, 1, None] + al * (sc * dt_[:, 1])[:, None]
    y1, y2 = _solve2(A11, A12, A22, m1, m2)
    kappa = sc[:, None] - (m1 * y1 + m2 * y2)
    d1, d2 = _solve2(A11, A12, A22, dt_[:, 0, None] + 0 * al, dt_[:, 1, None] + 0 * al)
    # W Jᵀ(α) = WJ0 + α We ⊗ Δ̃: u = W e_c − W Jᵀ y, z = W Jᵀ A⁻¹ Δ̃  (T, G, n)
    def wj(v1, v2):
        return (WJ0[:, None, :, 0] * v1[..., None] + WJ0[:, None, :, 1] * v2[..., None]
                + al[..., None] * We[:, None, :] * (dt_[:, 0, None, None] * v1[..., None]
                                                   + dt_[:, 1, None, None] * v2[..., None]))
    u = We[:, None, :] - wj(y1, y2)
    z = wj(d1, d2)
    uS0u = np.einsum("tgi,tij,tgj->tg", u, S0, u)
    var_g = np.einsum("tgi,tij,tgj->tg", z, S0, z)
    # lag-one: previous sample's (g, u, z), the run's first sample has none
    if prev is None:
        gp, up, zp = np.zeros(G), np.zeros((G, n)), np.zeros((G, n))
    else:
        gp, up, zp = prev
    g_prev = np.concatenate([gp[None], g[:-1]])
    u_prev = np.concatenate([up[None], u[:-1]])
    z_prev = np.concatenate([zp[None], z[:-1]])
    link = ~np.asarray(first, bool)[:, None]
    uS1u = np.einsum("tgi,tij,tgj->tg", u, S1, u_prev) * link
    cov_g = np.einsum("tgi,tij,tgj->tg", z, S1, z_prev) * link
    # d²C/dα² = −f'', f = bᵀA⁻¹b: f'' = 2 ex² Δ̃ᵀq − 4 ex qᵀv + 2 vᵀA⁻¹v − 2 s_c g², with
    # q = A⁻¹Δ̃ and v = A'G = Jwe g + Δ̃ (Jweᵀ G + 2α s_c g)
    sv = jg + 2 * al * sc[:, None] * g
    v1 = Jwe[:, 0, None] * g + dt_[:, 0, None] * sv
    v2 = Jwe[:, 1, None] * g + dt_[:, 1, None] * sv
    e1, e2 = _solve2(A11, A12, A22, v1, v2)
    dq = dt_[:, 0, None] * d1 + dt_[:, 1, None] * d2
    d2cost = -(2 * ex[:, None] ** 2 * dq - 4 * ex[:, None] * (d1 * v1 + d2 * v2)
               + 2 * (v1 * e1 + v2 * e2) - 2 * sc[:, None] * g * g)
    out = {"C": cost, "dC": dcost, "d2C": d2cost, "I": g * g * kappa, "Ib": var_g * kappa,
           "V": g * g * uS0u, "Vb": var_g * uS0u, "V1": 2 * g * g_prev * uS1u, "Vb1": 2 * cov_g * uS1u}
    return out, (g[-1].copy(), u[-1].copy(), z[-1].copy())


def _cross(A, S, B, out, SB):
    """out = Aᵀ S B for A (n, p), S (n, n), B (n, r) (S B first, into the scratch SB (n, r))."""
    n = S.shape[0]
    r = B.shape[1]
    for k in range(n):
        for j in range(r):
            acc = 0.0
            for m in range(n):
                acc += S[k, m] * B[m, j]
            SB[k, j] = acc
    for i in range(A.shape[1]):
        for j in range(r):
            acc = 0.0
            for k in range(n):
                acc += A[k, i] * SB[k, j]
            out[i, j] = acc


def _nodes_loop(x, qm, qn, lengths, Wb, S0b, S1b, widx, first, grid, lk, bins, pn, pv, plink,
                out, lagfirst, ext):
    """``node_terms`` as one loop (compiled with numba), each row on its own link lk[k], summed
    per bin: out[bins[k], lk[k] − 1] += the row's terms (KEYS order), and lagfirst[b, link − 1]
    holds the lag-one terms (V1, Vb1) of bin b's first row. A row has a lag-one term with the row
    before when that one was fitted (not ``first``) on the same link. The joints come from the
    step's posture qm (floating coordinates); ext[b, i] += (p_i, Δ_i, |Δ_i|) of every link i at
    the sample's posture qn. Row k's noise is Wb, S0b, S1b[widx[k]].

    u = W e_c s_u + W J0ᵀ w_u and z = W e_c s_z + W J0ᵀ w_z (s scalar, w 2-vector per node), so
    every quadratic form is O(1) per node from per-sample n×n products. Carried state: pn
    (N, G, 7) = (g, s_u, w_u, s_z, w_z) per link and node, pv (N, n, 3) = [W e_c, W J0ᵀ] of the
    link's last row, plink[0] the link of the last row (0: none)."""
    T, n = x.shape
    N = n - 3
    G = grid.size
    J0 = np.zeros((n, 2))
    M = np.empty((n, 3))                     # [W e_c, W J0ᵀ]
    Wx = np.empty(n)
    P0 = np.empty((3, 3))                    # Mᵀ S0 M
    P1 = np.zeros((3, 3))                    # Mᵀ S1 M_prev
    SB = np.empty((n, 3))
    A0 = np.zeros(3)
    b0 = np.zeros(2)
    Jw = np.zeros(2)
    jx = np.empty(N + 1)
    jz = np.empty(N + 1)
    for k in range(T):
        c = lk[k]
        bk = bins[k]
        head = k == 0 or bins[k - 1] != bk
        Wk = Wb[widx[k]]
        S0k = S0b[widx[k]]
        S1k = S1b[widx[k]]
        # the links at the sample's posture: Σ p_i, Δ_i, |Δ_i| per bin
        phi = qn[k, 2]
        px = qn[k, 0]
        pz = qn[k, 1]
        for i in range(N):
            phi += qn[k, 3 + i]
            dx = lengths[i] * math.sin(phi)
            dz = -lengths[i] * math.cos(phi)
            ext[bk, i, 0] += px
            ext[bk, i, 1] += pz
            ext[bk, i, 2] += dx
            ext[bk, i, 3] += dz
            ext[bk, i, 4] += lengths[i]
            px += dx
            pz += dz
        # the joints at the step's posture (relative to the base origin)
        phi = qm[k, 2]
        jx[0] = 0.0
        jz[0] = 0.0
        for i in range(N):
            phi += qm[k, 3 + i]
            jx[i + 1] = jx[i] + lengths[i] * math.sin(phi)
            jz[i + 1] = jz[i] - lengths[i] * math.cos(phi)
        J0[:, :] = 0.0
        J0[0, 0] = 1.0
        J0[1, 1] = 1.0
        for m in range(2, 3 + c):
            o = m - 3 if m > 3 else 0
            J0[m, 0] = -(jz[c - 1] - jz[o])
            J0[m, 1] = jx[c - 1] - jx[o]
        d0 = -(jz[c] - jz[c - 1])
        d1 = jx[c] - jx[c - 1]
        for i in range(n):
            s0 = 0.0
            s1 = 0.0
            se = 0.0
            sx = 0.0
            for j in range(n):
                s0 += Wk[i, j] * J0[j, 0]
                s1 += Wk[i, j] * J0[j, 1]
                if j >= 2 and j < 3 + c:
                    se += Wk[i, j]
                sx += Wk[i, j] * x[k, j]
            M[i, 0] = se
            M[i, 1] = s0
            M[i, 2] = s1
            Wx[i] = sx
        sc = 0.0
        ex = 0.0
        for m in range(2, 3 + c):
            sc += M[m, 0]
            ex += Wx[m]
        xWx = 0.0
        A0[:] = 0.0
        b0[:] = 0.0
        Jw[:] = 0.0
        for i in range(n):
            xWx += x[k, i] * Wx[i]
            A0[0] += J0[i, 0] * M[i, 1]
            A0[1] += J0[i, 0] * M[i, 2]
            A0[2] += J0[i, 1] * M[i, 2]
            b0[0] += J0[i, 0] * Wx[i]
            b0[1] += J0[i, 1] * Wx[i]
            Jw[0] += J0[i, 0] * M[i, 0]
            Jw[1] += J0[i, 1] * M[i, 0]
        _cross(M, S0k, M, P0, SB)
        lag = (not first[k]) and plink[0] == c
        if lag:
            _cross(M, S1k, pv[c - 1], P1, SB)
        p00, p01, p02, p11, p12, p22 = P0[0, 0], P0[0, 1], P0[0, 2], P0[1, 1], P0[1, 2], P0[2, 2]
        r00, r01, r02, r10, r11, r12 = P1[0, 0], P1[0, 1], P1[0, 2], P1[1, 0], P1[1, 1], P1[1, 2]
        r20, r21, r22 = P1[2, 0], P1[2, 1], P1[2, 2]
        o = out[bk, c - 1]
        lf = lagfirst[bk, c - 1]
        for gi in range(G):
            al = grid[gi]
            A11 = A0[0] + al * 2 * Jw[0] * d0 + al * al * sc * d0 * d0
            A12 = A0[1] + al * (Jw[0] * d1 + d0 * Jw[1]) + al * al * sc * d0 * d1
            A22 = A0[2] + al * 2 * Jw[1] * d1 + al * al * sc * d1 * d1
            idet = 1.0 / (A11 * A22 - A12 * A12)
            b1 = b0[0] + al * d0 * ex
            b2 = b0[1] + al * d1 * ex
            G1 = (A22 * b1 - A12 * b2) * idet
            G2 = (A11 * b2 - A12 * b1) * idet
            cost = xWx - (b1 * G1 + b2 * G2)
            g = d0 * G1 + d1 * G2
            m1 = Jw[0] + al * sc * d0
            m2 = Jw[1] + al * sc * d1
            y1 = (A22 * m1 - A12 * m2) * idet
            y2 = (A11 * m2 - A12 * m1) * idet
            kappa = sc - (m1 * y1 + m2 * y2)
            q1 = (A22 * d0 - A12 * d1) * idet
            q2 = (A11 * d1 - A12 * d0) * idet
            # W Jᵀ(α) = W J0ᵀ + α W e_c Δ̃ᵀ: u = W e_c − W Jᵀ y, z = W Jᵀ q
            su = 1.0 - al * (d0 * y1 + d1 * y2)
            sz = al * (d0 * q1 + d1 * q2)
            jg = Jw[0] * G1 + Jw[1] * G2
            dC = -2.0 * g * (ex - jg - al * sc * g)
            sv = jg + 2 * al * sc * g
            v1 = Jw[0] * g + d0 * sv
            v2 = Jw[1] * g + d1 * sv
            d2C = -(2 * ex * ex * (d0 * q1 + d1 * q2) - 4 * ex * (q1 * v1 + q2 * v2)
                    + 2 * ((A22 * v1 - A12 * v2) * v1 + (A11 * v2 - A12 * v1) * v2) * idet
                    - 2 * sc * g * g)
            # (s a + W_J w)ᵀ S (t a' + W_J' v) = s t P00 + s P0·v + t w·P·0 + wᵀ P·· v
            uS0u = (su * su * p00 - 2 * su * (p01 * y1 + p02 * y2)
                    + y1 * (p11 * y1 + p12 * y2) + y2 * (p12 * y1 + p22 * y2))
            zS0z = (sz * sz * p00 + 2 * sz * (p01 * q1 + p02 * q2)
                    + q1 * (p11 * q1 + p12 * q2) + q2 * (p12 * q1 + p22 * q2))
            uS1u = 0.0
            zS1z = 0.0
            gp = pn[c - 1, gi, 0]
            if lag:
                t_, v0, v1 = pn[c - 1, gi, 1], pn[c - 1, gi, 2], pn[c - 1, gi, 3]
                uS1u = (su * t_ * r00 + su * (r01 * v0 + r02 * v1) - t_ * (y1 * r10 + y2 * r20)
                        - y1 * (r11 * v0 + r12 * v1) - y2 * (r21 * v0 + r22 * v1))
                t_, v0, v1 = pn[c - 1, gi, 4], pn[c - 1, gi, 5], pn[c - 1, gi, 6]
                zS1z = (sz * t_ * r00 + sz * (r01 * v0 + r02 * v1) + t_ * (q1 * r10 + q2 * r20)
                        + q1 * (r11 * v0 + r12 * v1) + q2 * (r21 * v0 + r22 * v1))
            o[0, gi] += cost
            o[1, gi] += dC
            o[2, gi] += g * g * kappa
            o[3, gi] += zS0z * kappa
            o[4, gi] += g * g * uS0u
            o[5, gi] += zS0z * uS0u
            v6 = 2.0 * g * gp * uS1u
            v7 = 2.0 * zS1z * uS1u
            o[6, gi] += v6
            o[7, gi] += v7
            o[8, gi] += d2C
            if head:
                lf[0, gi] = v6
                lf[1, gi] = v7
            pn[c - 1, gi, 0] = g
            pn[c - 1, gi, 1] = su
            pn[c - 1, gi, 2] = -y1
            pn[c - 1, gi, 3] = -y2
            pn[c - 1, gi, 4] = sz
            pn[c - 1, gi, 5] = q1
            pn[c - 1, gi, 6] = q2
        for i in range(n):
            pv[c - 1, i, 0] = M[i, 0]
            pv[c - 1, i, 1] = M[i, 1]
            pv[c - 1, i, 2] = M[i, 2]
        plink[0] = c


_LOOP = None


def _compiled_loop():
    """The numba-compiled ``_nodes_loop`` (cached beside this file), or None without numba or
    with the kernels disabled (estimator.compiled.ENABLED)."""
    global _LOOP
    from estimator import compiled

    if not compiled.available():
        return None
    if _LOOP is None:
        from numba import njit

        jit = njit(cache=True, nogil=True, error_model="numpy")
        globals()["_cross"] = jit(_cross)
        _LOOP = jit(_nodes_loop)
    return _LOOP


def binned_terms(robot, x, qm, qn, lk, Wb, S0b, S1b, widx, first, bins, K: int, state: dict | None):
    """Node terms of fitted rows (each on its own link lk, 1…N; joints at the step postures qm)
    summed per bin (bins (T,) non-decreasing, 0…K−1), row k's noise Wb, S0b, S1b[widx[k]]:
    (sums (K, N, 9, G), lagfirst (K, N, 2, G): the lag-one terms of each bin's first row,
    ext (K, N, 5): Σ (p_i, Δ_i, |Δ_i|) of every link at the sample postures qn, state). ``state``
    carries the lag-one terms across calls (None: none). The compiled loop when numba is there;
    else ``node_terms`` per link (the reference)."""
    from estimator.localization import _joints_link_major

    T, n = x.shape
    N = n - 3
    G = GRID.size
    lk = np.asarray(lk, np.int64)
    bins = np.asarray(bins, np.int64)
    widx = np.asarray(widx, np.int64)
    first = np.asarray(first, bool)
    sums = np.zeros((K, N, len(KEYS), G))
    lagfirst = np.zeros((K, N, 2, G))
    ext = np.zeros((K, N, 5))
    lengths = np.asarray(robot.lengths_m, float)
    loop = _compiled_loop()
    if loop is not None:
        st = state if state and "fast" in state else {"fast": (np.zeros((N, G, 7)), np.zeros((N, n, 3)),
                                                               np.zeros(1, np.int64))}
        pn, pv, pl = st["fast"]
        loop(np.ascontiguousarray(x, float), np.ascontiguousarray(qm, float), np.ascontiguousarray(qn, float),
             lengths, np.ascontiguousarray(Wb), np.ascontiguousarray(S0b), np.ascontiguousarray(S1b), widx,
             np.ascontiguousarray(first, np.bool_), GRID, lk, bins, pn, pv, pl, sums, lagfirst, ext)
        return sums, lagfirst, ext, st
    st = state if state and "ref" in state else {"ref": {}, "last": 0}
    jx, jz = _joints_link_major(robot, qm)
    prev_link = np.r_[st["last"], lk[:-1]]
    first = first | (prev_link != lk)                 # a lag-one term only on the same link
    head = np.r_[True, bins[1:] != bins[:-1]]
    W, S0, S1 = Wb[widx], S0b[widx], S1b[widx]
    for c in np.unique(lk):
        m = np.flatnonzero(lk == c)
        part, st["ref"][int(c)] = node_terms(x[m], jx[:, m], jz[:, m], int(c), W[m], S0[m], S1[m],
                                            st["ref"].get(int(c)), first[m])
        rows = np.stack([part[key] for key in KEYS], axis=1)           # (m, 9, G)
        np.add.at(sums[:, c - 1], bins[m], rows)
        h = head[m]
        lagfirst[bins[m][h], c - 1] = rows[h][:, 6:8]
    nx, nz = _joints_link_major(robot, qn)
    per = np.stack([qn[:, 0, None] + nx[:-1].T, qn[:, 1, None] + nz[:-1].T,
                    np.diff(nx, axis=0).T, np.diff(nz, axis=0).T,
                    np.broadcast_to(lengths, (T, N))], -1)             # (T, N, 5)
    np.add.at(ext, bins, per)
    if T:
        st["last"] = int(lk[-1])
    return sums, lagfirst, ext, st


# ----------------------------------------------------------------------------- episode sums
class Layout:
    """One flat vector per episode (or segment, or fitted row) holding every sum: the node terms
    S (N, 8, G), rows per link, Σ link start p0 (N, 2), Σ Δ (N, 2), Σ |Δ| (N,), Σ per-sample
    bound² of α and its count (N,) each, and the number of rows."""

    def __init__(self, n_links: int):
        self.N = N = n_links
        self.G = G = GRID.size
        self.nS = N * len(KEYS) * G
        o = self.nS
        self.counts = slice(o, o + N)
        self.p0 = slice(o + N, o + 3 * N)
        self.dl = slice(o + 3 * N, o + 5 * N)
        self.length = slice(o + 5 * N, o + 6 * N)
        self.b2 = slice(o + 6 * N, o + 7 * N)
        self.bc = slice(o + 7 * N, o + 8 * N)
        self.samples = o + 8 * N
        self.size = o + 8 * N + 1

    def S(self, v):
        return v[..., :self.nS].reshape(v.shape[:-1] + (self.N, len(KEYS), self.G))

    def bins(self, sums, ext, lk, bound2, bins, K) -> np.ndarray:
        """(K, size) bin vectors: the binned node terms ``sums`` (K, N, 9, G), the binned point
        sums ``ext`` (K, N, 5: p, Δ, |Δ| of every link), and the rows' counts per link and
        per-sample bounds on their own link."""
        N = self.N
        v = np.zeros((K, self.size))
        v[:, :self.nS] = sums.reshape(K, -1)
        v[:, self.p0] = ext[:, :, 0:2].reshape(K, 2 * N)
        v[:, self.dl] = ext[:, :, 2:4].reshape(K, 2 * N)
        v[:, self.length] = ext[:, :, 4]
        np.add.at(v, (bins, self.counts.start + lk - 1), 1.0)
        ok = np.flatnonzero(np.isfinite(bound2))
        np.add.at(v, (bins[ok], self.b2.start + lk[ok] - 1), bound2[ok])
        np.add.at(v, (bins[ok], self.bc.start + lk[ok] - 1), 1.0)
        np.add.at(v, (bins, self.samples), 1.0)
        return v

    def link(self, v) -> np.ndarray:
        """The most frequent per-sample link (1…N; 0 without rows), (…,)."""
        cnt = v[..., self.counts]
        return np.where(cnt.max(axis=-1) > 0, np.argmax(cnt, axis=-1) + 1, 0)


def _hermite_min(x0, x1, f0, f1, d0, d1):
    """Minima of the cubic Hermite interpolants on [x0, x1] (arrays (M,)): (x, f, ok)."""
    h = x1 - x0
    a = 3 * (2 * f0 - 2 * f1 + h * d0 + h * d1)        # p'(s) = a s² + b s + c, s ∈ [0, 1]
    b = 2 * (-3 * f0 + 3 * f1 - 2 * h * d0 - h * d1)
    c = h * d0
    best_s = np.full(np.shape(f0), np.nan)
    best_f = np.full(np.shape(f0), np.inf)
    with np.errstate(all="ignore"):
        disc = b * b - 4 * a * c
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        lin = np.abs(a) < 1e-300 * (np.abs(b) + np.abs(c) + 1e-300)
        roots = [np.where(lin, -c / b, (-b - sq) / (2 * a)), np.where(lin, np.nan, (-b + sq) / (2 * a))]
        for s in roots:
            ok = (s >= 0) & (s <= 1) & (2 * a * s + b > 0)
            f = ((2 * s ** 3 - 3 * s ** 2 + 1) * f0 + (s ** 3 - 2 * s ** 2 + s) * h * d0
                 + (-2 * s ** 3 + 3 * s ** 2) * f1 + (s ** 3 - s ** 2) * h * d1)
            take = ok & (f < best_f)
            best_s = np.where(take, s, best_s)
            best_f = np.where(take, f, best_f)
    return x0 + best_s * h, best_f, np.isfinite(best_s)


def _quintic_refine(a0, C, dC, d2C, idx, iters: int = 6):
    """Newton on the derivative of the quintic Hermite interpolant of (C, C', C'') on the grid
    interval holding a0 (the cubic's minimum): error O(h⁶) against the cubic's O(h⁴)."""
    h = GRID[1] - GRID[0]
    j = np.clip(((a0 - GRID[0]) / h).astype(int), 0, GRID.size - 2)
    f0, f1 = C[idx, j], C[idx, j + 1]
    d0, d1 = h * dC[idx, j], h * dC[idx, j + 1]
    e0, e1 = h * h * d2C[idx, j], h * h * d2C[idx, j + 1]
    df = f1 - f0
    c = np.stack([f0, d0, e0 / 2, 10 * df - 6 * d0 - 4 * d1 - 1.5 * e0 + 0.5 * e1,
                  -15 * df + 8 * d0 + 7 * d1 + 1.5 * e0 - e1, 6 * df - 3 * (d0 + d1) - 0.5 * e0 + 0.5 * e1])
    s = (a0 - GRID[j]) / h
    for _ in range(iters):
        p1 = c[1] + s * (2 * c[2] + s * (3 * c[3] + s * (4 * c[4] + s * 5 * c[5])))
        p2 = 2 * c[2] + s * (6 * c[3] + s * (12 * c[4] + s * 20 * c[5]))
        with np.errstate(all="ignore"):
            step = np.where(p2 > 0, p1 / p2, 0.0)
        s = np.clip(s - step, -0.5, 1.5)
    return GRID[j] + s * h


REASONS = ("ok", "no samples", "out_of_bounds", "not_identifiable")


def solve_many(lay: Layout, V: np.ndarray, links: np.ndarray, precise: bool = True) -> dict:
    """For sum vectors V (M, size) and links (M,): α̂ (the cubic Hermite minimum of the profile
    cost; ``precise=False``: the zero of dC/dα interpolated linearly, for the slide test), its 1σ
    (sandwich V/I²), the bound 1/√I and the per-sample bound (1σ of α), the mean link start p0,
    Δ and |Δ| of the rows; ``reason`` indexes ``REASONS``."""
    V = np.atleast_2d(V)
    M = len(V)
    links = np.asarray(links, int)
    c = np.clip(links - 1, 0, lay.N - 1)
    idx = np.arange(M)
    S = lay.S(V)[idx, c]                               # (M, 8, G)
    k = V[:, lay.samples]
    nan = np.full(M, np.nan)
    with np.errstate(all="ignore"):
        kk = np.where(k > 0, k, np.nan)
        out = {"length_m": V[:, lay.length][idx, c] / kk,
               "p0": V[:, lay.p0].reshape(M, lay.N, 2)[idx, c] / kk[:, None],
               "dl": V[:, lay.dl].reshape(M, lay.N, 2)[idx, c] / kk[:, None],
               "alpha_bound_per_sample": np.sqrt(V[:, lay.b2][idx, c] / np.where(V[:, lay.bc][idx, c] > 0,
                                                                                 V[:, lay.bc][idx, c], np.nan))}
    C, dC = S[:, 0], S[:, 1]
    finite = np.all(np.isfinite(C), axis=1) & (k > 0) & (links >= 1)
    Cz = np.where(np.isfinite(C), C, np.inf)
    i = np.argmin(Cz, axis=1)
    best_x, best_f = nan.copy(), np.full(M, np.inf)
    G = lay.G
    for j in (i - 1, i):
        okj = (j >= 0) & (j < G - 1)
        jj = np.clip(j, 0, G - 2)
        if precise:
            x, f, ok = _hermite_min(GRID[jj], GRID[jj + 1], C[idx, jj], C[idx, jj + 1], dC[idx, jj],
                                    dC[idx, jj + 1])
        else:
            d0, d1 = dC[idx, jj], dC[idx, jj + 1]
            ok = (d0 <= 0) & (d1 >= 0) & (d1 > d0)
            with np.errstate(all="ignore"):
                x = GRID[jj] + (GRID[1] - GRID[0]) * (-d0) / (d1 - d0)
            f = np.where(ok, C[idx, jj], np.inf)
        take = okj & ok & (f < best_f)
        best_x = np.where(take, x, best_x)
        best_f = np.where(take, f, best_f)
    reason = np.where(~finite, 1, np.where(np.isfinite(best_x), 0, 2))
    a_hat = np.where(reason == 0, best_x, GRID[0])
    if precise:                                        # quintic Hermite (C, C', C'') refinement
        a_hat = np.where(reason == 0, _quintic_refine(a_hat, S[:, 0], S[:, 1], S[:, 8], idx), a_hat)
    # the sums at α̂: quadratic (Lagrange) through the three nearest nodes
    j = np.clip(np.rint((a_hat - GRID[0]) / (GRID[1] - GRID[0])).astype(int), 1, G - 2)
    u = (a_hat - GRID[j]) / (GRID[1] - GRID[0])
    w = np.stack([0.5 * u * (u - 1), 1 - u * u, 0.5 * u * (u + 1)], -1)      # nodes j−1, j, j+1
    at = (w[:, 0, None] * S[idx, :, j - 1] + w[:, 1, None] * S[idx, :, j]
          + w[:, 2, None] * S[idx, :, j + 1])                                   # (M, 8)
    info = at[:, 2] - at[:, 3]
    var = at[:, 4] + at[:, 6] - at[:, 5] - at[:, 7]
    bad = (reason == 0) & ~((info > 0) & (var > 0))
    reason = np.where(bad, 3, reason)
    good = reason == 0
    with np.errstate(all="ignore"):
        out.update(alpha=np.where(good, a_hat, np.nan), alpha_std=np.where(good, np.sqrt(var) / info, np.nan),
                   alpha_bound=np.where(good, 1 / np.sqrt(info), np.nan), reason=reason)
    return out


def solve(lay: Layout, v: np.ndarray, link: int) -> dict:
    """``solve_many`` for one sum vector: plain numbers, ``reason`` as text."""
    r = solve_many(lay, v[None], np.array([link]))
    out = {key: (val[0] if np.ndim(val) == 1 else val[0]) for key, val in r.items()}
    out = {key: (float(v_) if np.ndim(v_) == 0 else v_) for key, v_ in out.items()}
    out["reason"] = REASONS[int(r["reason"][0])]
    return out
