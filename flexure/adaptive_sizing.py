"""How far the next adaptive level refines: a step sized to just reach --rtol, within the budgets.

Rate. A goal's error estimate e falls as N^(−r) with the DOFs N, r between 2/3 (the goal's error
at the primal's energy rate N^(−p/3), the dual not resolved better) and 4/3 (= 2p/3, both resolved:
flexure.dwr). The a-priori rate RATE_PRIOR = 1 is their geometric mean: a step sized for a rate
above the true one falls short and costs one more level (at most about the DOFs of the level that
then reaches rtol), one sized for a rate below it overshoots by (e/rtol)^(1/r_prior − 1/r), without
bound as e/rtol grows; 2/3 (the first choice) took the paper disc at 1 % from 48.7 k to 220–249 k
DOFs where 128 k reach it (measured 2026-11-26: 95 → 40 s wall), while cross_frame, whose stiffness
converges at 0.79, needs a third level with either. Once two levels exist, each goal's own
observed rate r_g = ln(e_g,ℓ−1 / e_g,ℓ) / ln(N_ℓ / N_ℓ−1), clipped to [RATE_MIN, RATE_MAX].

Target. Every goal still above rtol (relative estimate e_g > rtol) needs N_g = N (e_g / rtol)^(1/r_g);
the next level aims at max_g N_g, at least MIN_GROWTH × N (a step whose estimates fall by less than
the calibration's MIN_DROP cannot measure their effectivity: (1 − MIN_DROP)^(−1/RATE_PRIOR)) and at
most MAX_GROWTH × N (one noisy estimate does not buy a huge level), and within the DOF and memory
budgets (the peak memory predicted above the process baseline, ``memory_dofs``).

Marks. Longest-edge bisection with closure adds about the same DOFs per marked element on a given
mesh (measured on the paper disc at 48.7 k DOFs, 2 rounds: 70–80 DOFs per marked element from 2 % to
25 % of the elements marked). So one topology-only trial bisection (no fields, no projection) of the
elements with the largest indicators measures that gain, and the count is scaled to the target
(``marks_for``).

Measured (2026-11-26, 2 shared cores at load 4–5, against main 0af84b6's Dörfler + MIN_MARKED steps in the
same session): paper disc at 2 %: level 1 86 k DOFs for a target of 87 k (was 136 k), wall 0.70×, CPU 0.76×;
three_spoke_thin STEP at 1 %: 71 k (was 134 k), wall 0.66×; cross_frame STEP at 1 %: 208 k (was 190 k), wall
1.2×; paper disc at 1 %: 249 k (was 137 k; the a-priori rate 2/3 against its observed ≈ 1.5), wall 1.1×.
Each run reached its rtol in two levels. The step lands where the estimate is just below rtol: the answer is
then only as honest as the estimate (three_spoke_thin's stiffness at 1 %: estimate 0.78 %, its error
against the deep reference 0.97 ± 0.50 %).
"""

from __future__ import annotations

import math

import numpy as np

RATE_PRIOR = 1.0
RATE_MIN = 1.0 / 3.0
RATE_MAX = 4.0 / 3.0
#: fraction of the elements bisected in the trial that measures the DOFs per marked element
TRIAL_SHARE = 0.05


def min_growth(min_drop: float) -> float:
    """The smallest step whose estimates fall by ``min_drop`` at the a-priori rate."""
    return (1.0 / (1.0 - min_drop)) ** (1.0 / RATE_PRIOR)


MAX_GROWTH = 6.0


def rates(prev: dict | None, cur: dict) -> np.ndarray:
    """Per goal (stiffness, then each gauge): the observed convergence rate of its relative estimate
    between two levels ({"dofs", "rel": [...]}) clipped to [RATE_MIN, RATE_MAX]; RATE_PRIOR without a
    previous level or where an estimate is not positive."""
    e = np.asarray(cur["rel"], float)
    if prev is None or prev["dofs"] >= cur["dofs"]:
        return np.full(len(e), RATE_PRIOR)
    ep = np.asarray(prev["rel"], float)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.log(ep / e) / math.log(cur["dofs"] / prev["dofs"])
    r = np.where(np.isfinite(r), r, RATE_PRIOR)
    return np.clip(r, RATE_MIN, RATE_MAX)


def target_dofs(n_dofs: int, rel: np.ndarray, rate: np.ndarray, rtol: float, min_grow: float) -> int:
    """DOFs of the next level: max over the goals above ``rtol`` of N (e_g/rtol)^(1/r_g), within
    [min_grow, MAX_GROWTH] × N (``min_grow`` alone where every goal is below rtol)."""
    rel = np.asarray(rel, float)
    open_ = rel > rtol
    need = n_dofs * np.max((rel[open_] / rtol) ** (1.0 / np.asarray(rate)[open_]), initial=min_grow)
    return int(min(max(need, min_grow * n_dofs), MAX_GROWTH * n_dofs))


def memory_dofs(n_dofs: int, base_gb: float, peak_gb: float, budget_gb: float) -> int:
    """The most DOFs whose peak stays within ``budget_gb``, the peak above the process's baseline
    ``base_gb`` (its resident memory before the first level: interpreter, libraries, the CAD kernel)
    taken proportional to the DOFs: peak(N) = base + (peak − base) N / n_dofs."""
    per = max(peak_gb - base_gb, 1e-9) / n_dofs
    return int(max(budget_gb - base_gb, 0.0) / per)


def marks_for(tm, comb: np.ndarray, target: int, rounds: int, forced=(), tries: int = 3) -> tuple[np.ndarray, dict]:
    """The elements to bisect so that the refined mesh has about ``target`` DOFs: the ``forced`` ones
    (the geometry criterion's) and the n largest of the combined indicators ``comb`` (one per element),
    n from topology-only trial bisections (module docstring): N(n) ≈ N_f + g n, N_f the DOFs with the
    forced ones alone, g measured by a trial at TRIAL_SHARE of the elements, then corrected by a secant
    step (closure makes N(n) slightly non-linear) while a trial is more than 10 % off. → (elements,
    info: the trials (marks, DOFs))."""
    from flexure.refine import TaggedMesh, bisect

    mesh = tm.mesh
    n_el = len(comb)
    order = np.argsort(-comb)
    forced = np.asarray(forced, np.int64)

    def dofs(n: int) -> int:
        if n == 0 and len(forced) == 0:
            return mesh.n_dofs
        out, _, _ = bisect(TaggedMesh(mesh, tm.face_tag, tm.edge_tag, tm.pending),
                           np.union1d(order[:n], forced), [], rounds=rounds)
        return out.mesh.n_dofs

    pts = [(0, dofs(0))]
    n = max(1, int(TRIAL_SHARE * n_el))
    for _ in range(tries):
        N = dofs(n)
        pts.append((n, N))
        if abs(N - target) <= 0.1 * target:
            break
        (n0, N0), (n1, N1) = sorted(pts, key=lambda p: abs(p[1] - target))[:2]
        g = (N1 - N0) / (n1 - n0) if n1 != n0 and N1 != N0 else max((N1 - pts[0][1]) / max(n1, 1), 1.0)
        n_new = int(np.clip(round(n1 + (target - N1) / max(g, 1e-9)), 0, n_el))
        if n_new == n:
            break
        n = n_new
    n, N = min(pts, key=lambda p: abs(p[1] - target))
    return np.union1d(order[:n], forced), {"trials": [list(map(int, p)) for p in pts], "marks": int(n),
                                            "predicted_dofs": int(N), "target_dofs": int(target)}
