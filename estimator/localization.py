"""Contact localization: where on which link, and how hard. Pure, vectorized functions of arrays.

All inputs are in floating coordinates [x, z, θ, q_1…q_N] (a fixed base has x = z = θ = 0; its hip
FT wrench is on the base rows), shaped (T, n). A contact is (link c, α, F) with F ON the robot at
p = p_c + α Δ_c, Δ_c = p_{c+1} − p_c, and generalized force τ_ext = J(α)ᵀ F:

    rows x, z:           F_x, F_z
    row θ and q_k, k≤c:  (p − o_k) × F = (p_c − o_k) × F + μ,   μ = α (Δ_c × F)
    rows q_k, k > c:     0                                        (o_θ = o_{q_1} = p_1, o_{q_k} = p_k)

``dynamic``: the observer residual r ≈ τ_ext on every row. For each link, (F_x, F_z, μ) is a
weighted LINEAR least-squares problem (3 unknowns, closed-form 3×3 solve per sample), weighted
by the inverse of the residual's noise covariance R when given (the maximum-likelihood fit); α =
μ/(Δ_c × F); if α ∉ [0, 1] it is clipped and F re-fitted. The link with the smallest residual wins.
With expected contacts (a stance foot) their forces join the unknowns (batched SVD solve).

``paper``: eqs. 6–9. R = C q̇ + G − B τ_sensor; the unexpected base wrench F_unexp = R_base −
F_base (eq. 7); the link from eq. 5 on the observer residual; α from the zero-moment condition

    α = (M_unexp − (p_c − p_1) × F) / (Δ_c × F),      F = (F_unexp,x, F_unexp,z)      (eq. 9)

Sign note: the paper writes τ_external on the left of eq. 1, hence its F_c = −F_unexp (eq. 8); in
our convention (forces ON the robot, M q̈ + C q̇ + G = τ + τ_ext) the same equations give F_c = +F_unexp.
It is quasi-static: it ignores M q̈, so a moving leg's inertial forces are read as contact.

Ill-conditioned answers have α = NaN (and p = NaN) with a reason code (``REASONS``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator import compiled, localization_loops
from estimator import dynamics as dyn
from userio.errors import InputError
from estimator.robot import Robot

REASONS = ("ok", "no_contact", "small_force", "parallel_to_link", "ambiguous_link",
           "out_of_bounds", "not_identifiable")
OK, NO_CONTACT, SMALL_FORCE, PARALLEL, AMBIGUOUS, OUT_OF_BOUNDS, NOT_IDENTIFIABLE = range(7)


@dataclass
class Localization:
    """Per-sample answer; link is 1-based (0 = none); reason indexes ``REASONS``."""

    link: np.ndarray            # (T,) int
    alpha: np.ndarray           # (T,)   NaN when ill-conditioned
    force_N: np.ndarray         # (T, 2) F = (Fx, Fz) ON the robot, world frame
    point_m: np.ndarray         # (T, 2) p = (px, pz), NaN when α is
    condition: np.ndarray       # (T,)   |F| |Δ| / |Δ × F| = 1/|sin∠(F, link)| (≥ 1; large = bad)
    reason: np.ndarray          # (T,) int8 index into REASONS
    cost: np.ndarray            # (T,)   weighted residual norm of the winning fit
    expected_force_N: np.ndarray | None = None   # (T, m, 2) forces at the expected contacts

    def reason_names(self) -> np.ndarray:
        return np.asarray(REASONS, dtype=object)[self.reason]


def _pick(arrays, index: np.ndarray) -> np.ndarray:
    """arrays[index[t]][t] for a short list of (T,) arrays (a loop over links, not samples)."""
    out = np.array(arrays[0], copy=True)
    for c in range(1, len(arrays)):
        np.copyto(out, arrays[c], where=index == c)
    return out


def _full(robot: Robot) -> Robot:
    return robot if robot.floating else robot.with_base(True)


def _cross(a, b):
    """2-D cross product a × b = a_x b_z − a_z b_x."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _weights(n: int, row_weights) -> np.ndarray:
    if row_weights is None:
        return np.ones(n)
    w = np.asarray(row_weights, float)
    if w.shape != (n,) or np.any(~np.isfinite(w)) or np.any(w <= 0):
        raise InputError(f"row weights: expected {n} finite values > 0")
    return w


def _moment_arms(joints: np.ndarray, c: int) -> np.ndarray:
    """a_k = p_c − o_k for the moment rows θ, q_1…q_c of link c (1-based): (T, c+1, 2)."""
    origins = np.concatenate([joints[:, :1], joints[:, :c]], axis=1)      # o_θ = p_1, o_qk = p_k
    return joints[:, c - 1:c] - origins


def weight_blocks(n: int, T: int, row_weights=None, weight=None):
    """(W (B, n, n), index (T,)) of the fit's weight matrices: sample t uses W[index[t]].

    ``weight``: the inverse residual covariance R⁻¹ — one (n, n) matrix, one per sample (T, n, n),
    or already (W, index); else the diagonal of ``row_weights`` (default ones)."""
    if weight is None:
        return np.diag(_weights(n, row_weights))[None], np.zeros(T, np.int64)
    if isinstance(weight, tuple):
        W, idx = weight
        return np.asarray(W, float), np.asarray(idx, np.int64)
    W = np.asarray(weight, float)
    if W.shape == (n, n):
        return W[None], np.zeros(T, np.int64)
    if W.shape != (T, n, n):
        raise InputError(f"weight: expected ({n}, {n}) or ({T}, {n}, {n}), got {W.shape}")
    return W, np.arange(T, dtype=np.int64)


def _link_design(jx, jz, c, n):
    """Columns (Fx, Fz, μ) of link c (1-based) on the rows [x, z, θ, q_1…q_N], (T, n, 3):

    rows x, z: (1, 0, 0), (0, 1, 0); moment row m ∈ {θ, q_1…q_c} with origin o_m:
    (−a_z, a_x, 1), a = p_c − o_m (o_θ = o_{q_1} = p_1, o_{q_k} = p_k); rows beyond q_c: 0."""
    T = jx.shape[1]
    H = np.zeros((T, n, 3))
    H[:, 0, 0] = 1.0
    H[:, 1, 1] = 1.0
    org = np.r_[0, 0:c]                                   # origins of rows 2 … 2 + c
    H[:, 2:3 + c, 0] = -(jz[c - 1] - jz[org]).T
    H[:, 2:3 + c, 1] = (jx[c - 1] - jx[org]).T
    H[:, 2:3 + c, 2] = 1.0
    return H


def _fit_link(r, W, jx, jz, c, N):
    """Weighted LS of (F, μ) on link c (1-based), min (r − H x)ᵀ W (r − H x), then α clipped to
    [0, 1] and F re-fitted there. r (T, n); W (T, n, n), the inverse residual covariance (or any
    positive definite weight); joints jx, jz (N+1, T) relative to the base origin.
    Returns alpha_free, alpha, Fx, Fz, cost (each (T,)), cost = √(eᵀ W e).
    """
    n = N + 3
    H = _link_design(jx, jz, c, n)
    WH = np.einsum("tij,tjk->tik", W, H)
    A = np.einsum("tik,til->tkl", H, WH)
    b = np.einsum("tik,ti->tk", WH, r)
    A11, A12, A13 = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
    A22, A23, A33 = A[:, 1, 1], A[:, 1, 2], A[:, 2, 2]
    b1, b2, b3 = b[:, 0], b[:, 1], b[:, 2]
    # symmetric 3×3 inverse by cofactors
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
    dx, dz = jx[c] - jx[c - 1], jz[c] - jz[c - 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha_free = mu / (dx * Fz - dz * Fx)
    alpha = np.clip(np.nan_to_num(alpha_free, nan=0.5), 0.0, 1.0)
    clipped = np.flatnonzero(alpha != alpha_free)
    if clipped.size:
        # F with α fixed: moment rows are (a_m + α Δ) × F → 2×2 normal equations, those samples only
        al = alpha[clipped]
        H2 = H[clipped, :, :2].copy()
        H2[:, 2:3 + c, 0] -= (al * dz[clipped])[:, None]
        H2[:, 2:3 + c, 1] += (al * dx[clipped])[:, None]
        WH2 = np.einsum("tij,tjk->tik", W[clipped], H2)
        B = np.einsum("tik,til->tkl", H2, WH2)
        d = np.einsum("tik,ti->tk", WH2, r[clipped])
        B11, B12, B22 = B[:, 0, 0], B[:, 0, 1], B[:, 1, 1]
        detB = B11 * B22 - B12 * B12
        Fx[clipped] = (B22 * d[:, 0] - B12 * d[:, 1]) / detB
        Fz[clipped] = (B11 * d[:, 1] - B12 * d[:, 0]) / detB
        mu[clipped] = al * (dx[clipped] * Fz[clipped] - dz[clipped] * Fx[clipped])
    e = r - np.einsum("tik,tk->ti", H, np.stack([Fx, Fz, mu], axis=-1))
    cost2 = np.einsum("ti,tij,tj->t", e, W, e)
    return alpha_free, alpha, Fx, Fz, np.sqrt(np.maximum(cost2, 0.0))


def _joints_link_major(rob: Robot, q: np.ndarray):
    """Joint positions relative to the base origin, jx, jz of shape (N+1, T)."""
    from estimator.observer import cumrows

    qT = np.ascontiguousarray(q.T)
    phi = qT[2] + cumrows(qT[3:])
    l = rob.lengths_m[:, None]
    jx = np.zeros((rob.n_links + 1, q.shape[0]))
    jz = np.zeros((rob.n_links + 1, q.shape[0]))
    jx[1:] = cumrows(l * np.sin(phi))
    jz[1:] = cumrows(-l * np.cos(phi))
    return jx, jz


def _flag(force, delta, reason, min_force_N, max_condition):
    """Condition figure and the small-force / parallel reasons (in place on ``reason``)."""
    fn = np.hypot(force[:, 0], force[:, 1])
    cr = np.abs(_cross(delta, force))
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = fn * np.hypot(delta[:, 0], delta[:, 1]) / cr
    condition = np.where(np.isnan(condition), np.inf, condition)
    reason[(reason == OK) & (condition > max_condition)] = PARALLEL
    # below the noise floor nothing else about the answer means anything: that flag wins
    reason[(reason != NOT_IDENTIFIABLE) & ~(fn >= min_force_N)] = SMALL_FORCE
    return condition


def localize_dynamic(robot: Robot, q: np.ndarray, residual: np.ndarray, *, expected=(),
                     row_weights=None, weight=None, min_force_N: float = 0.05,
                     max_condition: float = 20.0, ambiguity_tol: float = 1e-3,
                     position_tol_m: float = 0.005, bound_tol: float = 0.05) -> Localization:
    """Least-squares (F, α) on every link from the residual on all rows; smallest residual wins.

    ``weight``: the fit's weight matrix W, the inverse of the residual's noise covariance R
    (``weight_blocks``): then the fit is the maximum-likelihood (generalized least squares) one of
    r = J(α)ᵀF + n, n ~ N(0, R), and the cost is in noise standard deviations. Without it the
    diagonal ``row_weights`` (default ones: the unweighted fit).

    q, residual: (T, n) floating coordinates. ``expected``: sequence of (link, α) contacts whose
    forces are estimated jointly (e.g. ``[(N, 1.0)]`` for a stance foot). Flags: |F| < min_force_N
    → small_force; condition > max_condition → parallel_to_link; another link fits within
    ``ambiguity_tol`` at a point more than ``position_tol_m`` away → ambiguous_link; the free α
    beyond [−bound_tol, 1 + bound_tol] → out_of_bounds; rank-deficient with the expected
    contacts → not_identifiable.

    Without expected contacts the per-sample solve runs as one compiled loop when numba is there
    (``estimator.localization_loops``; the numpy form below is its reference, equal to rounding).
    """
    rob = _full(robot)
    q = np.atleast_2d(np.asarray(q, float))
    r = np.atleast_2d(np.asarray(residual, float))
    N = rob.n_links
    n = N + 3
    if q.shape[-1] != n or r.shape != q.shape:
        raise InputError(f"localize: q and residual must both be (T, {n}), got {q.shape}, {r.shape}")
    Wb, widx = weight_blocks(n, len(q), row_weights, weight)
    args = (min_force_N, max_condition, ambiguity_tol, position_tol_m, bound_tol)
    if not expected and compiled.available():       # the same per-sample solve, compiled
        link, alpha, force, point, condition, reason, cost = localization_loops.localize(
            rob, q, r, (Wb, widx), min_force_N=min_force_N, max_condition=max_condition,
            ambiguity_tol=ambiguity_tol, position_tol_m=position_tol_m, bound_tol=bound_tol)
        return Localization(link=link, alpha=alpha, force_N=force, point_m=point,
                            condition=condition, reason=reason, cost=cost)
    chunk = 8192 if not expected else 4096          # cache-sized blocks (a loop over blocks)
    if len(q) > chunk:
        out = None
        for s in range(0, len(q), chunk):
            part = localize_dynamic(rob, q[s:s + chunk], r[s:s + chunk], expected=expected,
                                    weight=(Wb, widx[s:s + chunk]), min_force_N=min_force_N,
                                    max_condition=max_condition, ambiguity_tol=ambiguity_tol,
                                    position_tol_m=position_tol_m, bound_tol=bound_tol)
            if out is None:                    # preallocate every field for the whole batch
                out = {f: None if getattr(part, f) is None else
                       np.empty((len(q),) + getattr(part, f).shape[1:], getattr(part, f).dtype)
                       for f in Localization.__dataclass_fields__}
            for f, arr in out.items():
                if arr is not None:
                    arr[s:s + chunk] = getattr(part, f)
        return Localization(**out)
    W = Wb[widx]                                    # (T, n, n)
    if expected:
        return _localize_with_expected(rob, q, r, W, list(expected), *args)
    T = len(q)
    jx, jz = _joints_link_major(rob, q)
    fits = [_fit_link(r, W, jx, jz, c, N) for c in range(1, N + 1)]
    costs = np.stack([f[4] for f in fits])                            # (N, T)
    if N > 1:
        order = np.argsort(costs, axis=0, kind="stable")
        best, second = order[0], order[1]
    else:
        best = np.zeros(T, dtype=int)
    take = lambda k, which: _pick([f[k] for f in fits], which)   # noqa: E731  (N ≤ 32 links)
    alpha_free, alpha = take(0, best), take(1, best)
    force = np.stack([take(2, best), take(3, best)], axis=-1)
    cost = take(4, best)
    link = best + 1
    sx, sz = _pick(jx[:-1], best), _pick(jz[:-1], best)
    delta = np.stack([_pick(jx[1:], best) - sx, _pick(jz[1:], best) - sz], axis=-1)
    point = np.stack([q[:, 0] + sx, q[:, 1] + sz], axis=-1) + alpha[:, None] * delta
    reason = np.zeros(T, dtype=np.int8)
    reason[~((alpha_free >= -bound_tol) & (alpha_free <= 1 + bound_tol))] = OUT_OF_BOUNDS
    if N > 1:
        close = take(4, second) - cost < ambiguity_tol
        if close.any():
            a2 = take(1, second)
            s2x, s2z = _pick(jx[:-1], second), _pick(jz[:-1], second)
            e2x, e2z = _pick(jx[1:], second), _pick(jz[1:], second)
            p2 = np.stack([q[:, 0] + s2x + a2 * (e2x - s2x), q[:, 1] + s2z + a2 * (e2z - s2z)], -1)
            far = np.hypot(*(p2 - point).T) > position_tol_m
            # a rival whose force runs along its own link fixes no α there: its point could be
            # anywhere on that link (e.g. a force through the knee fits link 1 at α = 1 and link 2
            # anywhere on its line of action), so it is as good as far
            f2 = np.stack([take(2, second), take(3, second)], axis=-1)
            d2 = np.stack([e2x - s2x, e2z - s2z], axis=-1)
            with np.errstate(divide="ignore", invalid="ignore"):
                cond2 = np.hypot(*f2.T) * np.hypot(*d2.T) / np.abs(_cross(d2, f2))
            far |= ~(cond2 <= max_condition)
            reason[(reason == OK) & close & far] = AMBIGUOUS
    condition = _flag(force, delta, reason, min_force_N, max_condition)
    bad = reason != OK
    alpha = np.where(bad, np.nan, alpha)
    point = np.where(bad[:, None], np.nan, point)
    return Localization(link=link, alpha=alpha, force_N=force, point_m=point, condition=condition,
                        reason=reason, cost=cost)


# ----------------------------------------------------------------------------- expected contacts
def expected_jacobians(robot: Robot, q: np.ndarray, expected) -> np.ndarray:
    """Stacked Jᵀ columns of the expected contacts, (T, n, 2m)."""
    rob = _full(robot)
    cols = []
    for link, alpha in expected:
        if not (1 <= int(link) <= rob.n_links) or not (0.0 <= float(alpha) <= 1.0):
            raise InputError(f"expected contact: link must be 1…{rob.n_links} and α in [0, 1], "
                             f"got ({link}, {alpha})")
        cols.append(np.swapaxes(dyn.point_jacobian(rob, q, int(link), float(alpha)), -1, -2))
    return np.concatenate(cols, axis=-1)


def _lstsq_batched(A, b, rcond=1e-9):
    """Batched least squares by SVD: x (T, k), rank-deficient flag (T,)."""
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    deficient = s[:, -1] <= rcond * s[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(s > rcond * s[:, :1], 1.0 / s, 0.0)
    x = np.einsum("tji,tj,tkj,tk->ti", Vt, inv, U, b)
    return x, deficient


def explain_expected(robot: Robot, q: np.ndarray, residual: np.ndarray, expected, row_weights=None):
    """Fit the expected contacts alone: (unexplained residual (T, n), their forces (T, m, 2))."""
    rob = _full(robot)
    q = np.atleast_2d(np.asarray(q, float))
    r = np.atleast_2d(np.asarray(residual, float))
    w = np.sqrt(_weights(rob.n_links + 3, row_weights))
    Je = expected_jacobians(rob, q, expected)
    x, _ = _lstsq_batched(w[:, None] * Je, w * r)
    return r - np.einsum("tnk,tk->tn", Je, x), x.reshape(len(q), -1, 2)


def _link_columns(joints, c, N, alpha=None):
    """Columns of link c: (T, n, 3) for (Fx, Fz, μ), or (T, n, 2) for F at a fixed α."""
    T = joints.shape[0]
    a = _moment_arms(joints, c)
    if alpha is not None:
        a = a + alpha[:, None, None] * (joints[:, c] - joints[:, c - 1])[:, None, :]
    cols = np.zeros((T, N + 3, 2 if alpha is not None else 3))
    cols[:, 0, 0] = 1.0
    cols[:, 1, 1] = 1.0
    rows = np.r_[2, 3:3 + c]
    cols[:, rows, 0] = -a[..., 1]
    cols[:, rows, 1] = a[..., 0]
    if alpha is None:
        cols[:, rows, 2] = 1.0
    return cols


def _localize_with_expected(rob, q, r, W, expected, min_force_N, max_condition, ambiguity_tol,
                            position_tol_m, bound_tol):
    N = rob.n_links
    T = len(q)
    S = np.swapaxes(np.linalg.cholesky(W), -1, -2)     # Sᵀ S = W: ‖S e‖² = eᵀ W e
    Sr = np.einsum("tij,tj->ti", S, r)
    joints, _ = dyn.forward_kinematics(rob, q)
    Je = expected_jacobians(rob, q, expected)                   # (T, n, 2m)
    me = Je.shape[-1]
    results = []
    for c in range(1, N + 1):
        A = np.concatenate([Je, _link_columns(joints, c, N)], axis=-1)
        x, deficient = _lstsq_batched(S @ A, Sr)
        F = x[:, me:me + 2]
        mu = x[:, me + 2]
        delta = joints[:, c] - joints[:, c - 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            alpha_free = mu / _cross(delta, F)
        alpha = np.clip(np.nan_to_num(alpha_free, nan=0.5), 0.0, 1.0)
        clipped = (alpha != alpha_free) & ~deficient
        if np.any(clipped):
            A2 = np.concatenate([Je, _link_columns(joints, c, N, alpha)], axis=-1)
            x2, def2 = _lstsq_batched(S @ A2, Sr)
            x = np.where(clipped[:, None], np.concatenate([x2, (alpha * _cross(delta, x2[:, me:]))[:, None]],
                                                          axis=-1), x)
            deficient = deficient | (clipped & def2)
            A = np.where(clipped[:, None, None],
                         np.concatenate([A2, np.zeros((T, N + 3, 1))], axis=-1), A)
        e = np.einsum("tij,tj->ti", S, r - np.einsum("tnk,tk->tn", A, x))
        results.append((alpha_free, alpha, x, np.sqrt((e * e).sum(-1)), deficient))
    costs = np.stack([res[3] for res in results], axis=-1)
    order = np.argsort(costs, axis=-1, kind="stable")
    best = order[:, 0]
    idx = np.arange(T)
    pick = lambda k: np.stack([res[k] for res in results], axis=1)[idx, best]  # noqa: E731
    alpha_free, alpha, x, deficient = pick(0), pick(1), pick(2), pick(4)
    force = x[:, me:me + 2]
    start = joints[idx, best]
    delta = joints[idx, best + 1] - start
    point = start + alpha[:, None] * delta
    reason = np.zeros(T, dtype=np.int8)
    reason[deficient] = NOT_IDENTIFIABLE
    reason[(reason == OK) & ~((alpha_free >= -bound_tol) & (alpha_free <= 1 + bound_tol))] = OUT_OF_BOUNDS
    if N > 1:
        second = order[:, 1]
        a2 = np.stack([res[1] for res in results], axis=1)[idx, second]
        p2 = joints[idx, second] + a2[:, None] * (joints[idx, second + 1] - joints[idx, second])
        close = costs[idx, second] - costs[idx, best] < ambiguity_tol
        far = np.hypot(*(p2 - point).T) > position_tol_m
        reason[(reason == OK) & close & far] = AMBIGUOUS
        # a rank-deficient candidate that fits as well: the data cannot tell them apart
        def2 = np.stack([res[4] for res in results], axis=1)[idx, second]
        reason[(reason == OK) & close & def2] = NOT_IDENTIFIABLE
    condition = _flag(force, delta, reason, min_force_N, max_condition)
    bad = reason != OK
    nid = reason == NOT_IDENTIFIABLE
    force = np.where(nid[:, None], np.nan, force)
    expected_force = np.where(nid[:, None], np.nan, x[:, :me]).reshape(T, -1, 2)
    return Localization(link=np.where(nid, 0, best + 1), alpha=np.where(bad, np.nan, alpha),
                        force_N=force, point_m=np.where(bad[:, None], np.nan, point),
                        condition=condition, reason=reason, cost=costs[idx, best],
                        expected_force_N=expected_force)


# ----------------------------------------------------------------------------- paper (eqs. 6–9)
def bias_forces(robot: Robot, q: np.ndarray, dq: np.ndarray, chunk: int = 8192) -> np.ndarray:
    """C(q, q̇) q̇ + G(q) in floating coordinates, (T, n) (``observer.chain_terms``, chunked)."""
    from estimator.observer import chain_terms

    q = np.atleast_2d(np.asarray(q, float))
    dq = np.atleast_2d(np.asarray(dq, float))
    out = np.empty(q.shape)
    for s in range(0, len(q), chunk):
        terms = chain_terms(robot, q[s:s + chunk], dq[s:s + chunk], want=("Cdq", "G"))
        out[s:s + chunk] = terms["Cdq"] + terms["G"]
    return out


def localize_paper(robot: Robot, q: np.ndarray, dq: np.ndarray, tau_meas: np.ndarray,
                   link: np.ndarray, *, min_force_N: float = 0.05,
                   max_condition: float = 20.0, bias=None) -> Localization:
    """Eqs. 6–9 on the link chosen by eq. 5 (``link``, 1-based, 0 = not isolated), per sample.

    tau_meas: [Fx, Fz, My, τ_1…τ_N] (T, n). α outside [0, 1] → NaN, reason out_of_bounds
    (the paper: "the force lies out-of-bounds").
    """
    rob = _full(robot)
    q = np.atleast_2d(np.asarray(q, float))
    tau_meas = np.atleast_2d(np.asarray(tau_meas, float))
    T = len(q)
    R = bias_forces(rob, q, dq) if bias is None else bias          # eq. 6 (B τ has no base rows)
    unexp = R[:, :3] - tau_meas[:, :3]                               # eq. 7
    force = unexp[:, :2].copy()                                      # eq. 8 (our sign, see module)
    joints, _ = dyn.forward_kinematics(rob, q)
    link = np.asarray(link, int)
    c0 = np.clip(link - 1, 0, rob.n_links - 1)
    idx = np.arange(T)
    start = joints[idx, c0]
    delta = joints[idx, c0 + 1] - start
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = (unexp[:, 2] - _cross(start - joints[:, 0], force)) / _cross(delta, force)   # eq. 9
    reason = np.zeros(T, dtype=np.int8)
    reason[link == 0] = AMBIGUOUS
    condition = _flag(force, delta, reason, min_force_N, max_condition)
    inside = (alpha >= -1e-9) & (alpha <= 1 + 1e-9)
    reason[(reason == OK) & ~inside] = OUT_OF_BOUNDS
    alpha = np.clip(alpha, 0.0, 1.0)
    point = start + alpha[:, None] * delta
    bad = reason != OK
    return Localization(link=link, alpha=np.where(bad, np.nan, alpha), force_N=force,
                        point_m=np.where(bad[:, None], np.nan, point), condition=condition,
                        reason=reason, cost=np.full(T, np.nan))
