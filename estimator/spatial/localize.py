"""Contacts on link surfaces in 3-D, from the observer residual.

A point contact on body b at p (world, relative to the base origin O) with force F gives
τ_ext = A_b [F; p × F], A_b the Jacobian columns (twists at O, estimator.spatial.model.columns)
of the coordinates that move b, restricted to the rows that are equations. Per candidate body,
vectorized over samples, with the residual whitened by L (L Lᵀ = R⁻¹, the no-contact covariance):

1. the wrench w = [F; m] = argmin ‖L(r − A_b w)‖² (six unknowns: the FT rows fix it; the
   sensed joint rows add equations);
2. its line of action: a pure force transmits m = p × F, so p lies on p₀ + s F̂ with
   p₀ = F × m / |F|² (the moment's part along F, the wrench's pitch, is left out);
3. the line enters the body's collision solids (estimator.spatial.geometry) where F pushes into
   the surface (F̂ · n < 0): that is the contact point; a body without solids is located on its
   segment (the point nearest the line; flagged ``no_geometry``);
4. a pure force at that point is refitted, F = argmin ‖L(r − A_b [I; [p]×] F)‖², and its
   χ²_b = ‖L(r − …)‖² is the body's whitened misfit.

The body with the smallest χ² wins (the whitened isolation test). Refused (NaN, a reason):
|F| below the floor (``small_force``), a line meeting the surface at a grazing angle, 1/|F̂·n| >
``max_condition`` (``grazing``), a line that enters no candidate's solids (``off_surface``), a
second body within ``ambiguity_chi2`` of the best χ² at a point more than ``position_tol_m``
away (``ambiguous_link``: the data cannot tell them apart, e.g. the joint between them has no
torque sensor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.spatial import geometry as geo
from estimator.spatial.model import _skew, columns, cross, moves
from estimator.spatial.observer import used_rows

REASONS = ("ok", "no_contact", "small_force", "grazing", "off_surface", "ambiguous_link",
           "no_geometry", "several_entries")
OK, NO_CONTACT, SMALL_FORCE, GRAZING, OFF_SURFACE, AMBIGUOUS, NO_GEOMETRY, SEVERAL = range(8)


def _choose_entry(s_all, n_all, i_all, d, tol, cone_condition):
    """One crossing per line among a body's inward crossings (sorted along the line): the first
    if they all lie within ``tol`` of it; else the first inside the friction cone (the force
    within arccos(1/cone_condition) of the inward normal) if the cone's crossings lie within
    ``tol`` of each other; else the first, flagged ``several`` (a concave surface the line enters
    more than once: the wrench cannot tell where)."""
    S = len(s_all)
    rows = np.arange(S)
    valid = np.isfinite(s_all)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = 1.0 / np.abs(np.einsum("ski,si->sk", n_all, d))
    last = np.max(np.where(valid, s_all, -np.inf), axis=1)
    single = ~(last - s_all[:, 0] > tol)
    in_cone = valid & (cond <= cone_condition)
    k_in = np.argmax(in_cone, axis=1)
    with np.errstate(invalid="ignore"):
        spread_in = np.max(np.where(in_cone, s_all, -np.inf), axis=1) - s_all[rows, k_in]
    use_cone = ~single & in_cone.any(axis=1) & ~(spread_in > tol)
    k = np.where(use_cone, k_in, 0)
    several = ~single & ~use_cone
    return s_all[rows, k], n_all[rows, k], i_all[rows, k], several


@dataclass
class SpatialLocalization:
    body: np.ndarray            # (S,) body index (−1: none)
    link: np.ndarray            # (S,) object: URDF link name of the solid hit ('' none)
    point_body: np.ndarray      # (S, 3) in the body frame (NaN when refused)
    force_N: np.ndarray         # (S, 3) world, ON the robot
    chi2: np.ndarray            # (S,) the winner's whitened misfit
    condition: np.ndarray       # (S,) 1/|F̂·n| (≥ 1; large: grazing)
    reason: np.ndarray          # (S,) int8 into REASONS


def _solve(A, b):
    """Batched least squares by the normal equations (A (S, m, k) full column rank), compiled."""
    from estimator.spatial.tree import lstsq_small

    return lstsq_small(A, b)


def localize(model, surfaces, q, r, Linv, *, min_force_N=0.05, max_condition=20.0,
             ambiguity_chi2=6.63, position_tol_m=0.005, ambiguity_tol=None,
             cone_condition=2.0) -> SpatialLocalization:
    """Per sample (q (S, nq), r (S, nv) all rows, Linv (nu, nu) or (S, nu, nu)): module doc.

    ``ambiguity_tol`` (the planar dynamic method's rule, for an unweighted fit, Linv = I): two
    bodies are ambiguous when their residual norms √χ² differ by less than it (instead of χ²
    by less than ``ambiguity_chi2``)."""
    q = np.atleast_2d(q)
    r = np.atleast_2d(r)
    S_ = len(q)
    rows = used_rows(model)
    cols, _, _, (R, pos) = columns(model.tree, q)
    A = cols[:, rows]                                     # (S, nu, 6)
    L = np.broadcast_to(Linv, (S_,) + Linv.shape[-2:])
    rw = (L @ r[:, rows][..., None])[..., 0]
    mv = moves(model.tree)[rows]
    NB = model.tree.n_bodies
    cost = np.full((S_, NB), np.inf)
    pts = np.full((S_, NB, 3), np.nan)                    # body frame
    pw = np.full((S_, NB, 3), np.nan)                     # world, relative to O
    force = np.full((S_, NB, 3), np.nan)
    cond = np.full((S_, NB), np.inf)
    which = np.full((S_, NB), -1)
    fnorm = np.zeros((S_, NB))
    several = np.zeros((S_, NB), bool)
    for b in range(NB):
        Ab = A * mv[:, b][None, :, None]
        Aw = L @ Ab
        w = _solve(Aw, rw)
        F, m = w[:, :3], w[:, 3:]
        fn = np.linalg.norm(F, axis=1)
        fnorm[:, b] = fn
        with np.errstate(divide="ignore", invalid="ignore"):
            d = F / fn[:, None]
            p0 = cross(F, m) / (fn * fn)[:, None]
        good = fn > 0
        d = np.where(good[:, None], d, np.array([0.0, 0.0, 1.0]))
        p0 = np.where(good[:, None], p0, 0.0)
        Rb, pb = R[:, b], pos[:, b]
        RbT = Rb.transpose(0, 2, 1)
        o_b = (RbT @ (p0 - pb)[..., None])[..., 0]
        d_b = (RbT @ d[..., None])[..., 0]
        surf = surfaces[b]
        if surf.has_geometry:
            s, normal, hit, sev = _choose_entry(*geo.body_entries(surf, o_b, d_b), d_b,
                                                position_tol_m, cone_condition)
            point = o_b + s[:, None] * d_b
            several[:, b] = sev
            ok = np.isfinite(s)
            with np.errstate(divide="ignore"):
                cond[:, b] = np.where(ok, 1.0 / np.abs(np.einsum("si,si->s", normal, d_b)), np.inf)
            which[:, b] = hit
        else:
            point, _, _ = geo.segment_point(surf, o_b, d_b)
            ok = np.ones(S_, bool)
            cond[:, b] = 1.0
        pwb = pb + (Rb @ point[..., None])[..., 0]
        Ap = Aw[:, :, :3] + Aw[:, :, 3:] @ _skew(np.nan_to_num(pwb))
        Fp = _solve(Ap, rw)
        e = rw - (Ap @ Fp[..., None])[..., 0]
        c2 = np.einsum("si,si->s", e, e)
        cost[:, b] = np.where(ok, c2, np.inf)
        pts[:, b], pw[:, b], force[:, b] = point, pwb, Fp
    order = np.argsort(cost, axis=1, kind="stable")
    best = order[:, 0]
    idx = np.arange(S_)
    c_best = cost[idx, best]
    reason = np.zeros(S_, np.int8)
    reason[~np.isfinite(c_best)] = OFF_SURFACE
    if NB > 1:
        second = order[:, 1]
        with np.errstate(invalid="ignore"):
            if ambiguity_tol is None:
                close = cost[idx, second] - c_best < ambiguity_chi2
            else:
                close = np.sqrt(cost[idx, second]) - np.sqrt(c_best) < ambiguity_tol
        far = np.linalg.norm(pw[idx, second] - pw[idx, best], axis=1) > position_tol_m
        reason[(reason == OK) & close & far] = AMBIGUOUS
    condition = cond[idx, best]
    reason[(reason == OK) & several[idx, best]] = SEVERAL
    reason[(reason == OK) & (condition > max_condition)] = GRAZING
    reason[(reason == OK) & np.array([not surfaces[b].has_geometry for b in best])] = NO_GEOMETRY
    F_best = force[idx, best]
    reason[~(np.linalg.norm(np.nan_to_num(F_best), axis=1) >= min_force_N)
           & ~(fnorm[idx, best] >= min_force_N)] = SMALL_FORCE
    bad = (reason != OK) & (reason != NO_GEOMETRY)
    # the link name of (body, solid index): solids first, the body's own name at index −1
    width = max(len(sf.solids) for sf in surfaces) + 1
    table = np.empty((NB, width), dtype=object)
    for sf in surfaces:
        table[sf.body, :] = sf.name
        for i, (name, _) in enumerate(sf.solids):
            table[sf.body, i] = name
    link = table[best, which[idx, best]]
    point = np.where(bad[:, None], np.nan, pts[idx, best])
    off = reason == OFF_SURFACE
    F_out = np.where(off[:, None], np.nan, F_best)
    return SpatialLocalization(body=np.where(off, -1, best), link=np.where(off, "", link),
                               point_body=point, force_N=F_out, chi2=c_best, condition=condition,
                               reason=reason)


def identifiability(model, surfaces) -> list[dict]:
    """Per body: the sensed joints on its path (whose rows separate it from other bodies), the
    bodies it cannot be told apart from by the residual (the same sensed joints moving them:
    only the line of action's crossing of their surfaces separates them), and whether it can be
    located on a surface (collision geometry) or only on its segment."""
    mv = moves(model.tree)[used_rows(model)]
    out = []
    for b in range(model.tree.n_bodies):
        same = [surfaces[c].name for c in range(model.tree.n_bodies)
                if c != b and np.array_equal(mv[:, c], mv[:, b])]
        sensed = [model.joint_names[k - 6] for k in used_rows(model)[6:] if mv[list(used_rows(model)).index(k), b]]
        out.append({"link": surfaces[b].name,
                    "links_on_body": sorted({n for n, _ in surfaces[b].solids}) or [surfaces[b].name],
                    "sensed_joints_moving_it": sensed,
                    "confused_with": same,
                    "located_on": "surface" if surfaces[b].has_geometry else "segment (no collision geometry)",
                    "line_of_action": "identifiable (six-axis FT sensor)"})
    return out
