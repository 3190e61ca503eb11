"""Discretisation error estimate of a flexure analysis: the same design on several mesh levels.

Levels: the whole size function × f (h_f(x) = f·h(x): far size, gauge size and grading),
f = √2, 1, 1/√2 (then 1/2, 1/(2√2), ... under ``rtol``); the answer is the finest level, h of a level
is f. Rule for the levels that enter the estimate: a level whose element size at the gauges is
larger than the gauge grid's smaller side (fewer than MIN_GAUGE_ELEMENTS = 1 element across the
grid) is outside the asymptotic range of the gauge strain and is left out (stated in the method).
On every reference geometry the former coarsest level f = 2 (then 0.83 elements across a grid) read
the strain 2–3 % off the trend of the finer ones, which made the three-level estimate up to 20×
too wide; that is why the levels are √2, 1, 1/√2 and why the rule guards custom levels.

For a figure Q with values Q_1, Q_2, Q_3 on the three finest usable levels (h_1 > h_2 > h_3) the
observed order p solves

    (Q_1 − Q_2) / (Q_2 − Q_3) = (h_1^p − h_2^p) / (h_2^p − h_3^p)          (Richardson)

and the error of the finest answer is estimated as the grid convergence index (Roache 1994)

    e = F_s · |Q_3 − Q_2| / ((h_2/h_3)^p − 1),   F_s = 1.25 (three levels), 3 (two levels, p nominal).

p is clipped to [0.5, 4]. An order above the nominal one (FIGURES) is a lucky pair of levels, not a
rate to extrapolate with: the estimate then uses the nominal order and, for |Q_3 − Q_2|, the larger
of the change seen and the change the first one implies at that order (on the thick disc's STL the
last change was 0.02 % while the answer was 0.14 % off). An order below the figure's asymptotic
minimum (MIN_ORDER) is not a rate either: every singularity of these parts (a sharp re-entrant
edge, the edge of a support) has an exponent λ ≥ ½, so in the asymptotic range P2's gauge strain,
sensitivity and stiffness converge at least as h^(2λ) ≥ h (the energy directly, a gauge reading
through the pollution of its dual solution); an observed order below 1 there is the scatter of
non-nested meshes on two small changes, and extrapolating with it (the denominator (√2)^p − 1 is
0.19 at p = ½ against 0.41 at p = 1) made the strain estimates many times their true error. It
is used at 1 then (stated in the method). With it and the gauge sizing of meshing.SIZES (4.7
elements across a grid at the answer level, 2.4 before) three of the five reference strains'
estimates are within 1.5–2.1× the far end of their true error, two at 3.2× and 6.2× (were
4.2–17×), the stiffnesses' within 1.0–1.3×, and every estimate still brackets its error
(tests/data/fem_reference/levels.json). The floor
is not applied to P1, whose locked levels are pre-asymptotic (the paper disc's P1 stiffness showed
order 0.75 on one set of meshes, 18.5 % off, where an order-1 estimate gives 12.9 %), nor to the
safety factor, whose peak stress may diverge at a sharp edge. Oscillatory convergence (the two
changes of opposite sign) has no order: e = F_s · max(|Q_1 − Q_2|, |Q_2 − Q_3|), stated as such.
The estimate is a bound-like figure (not a 1σ).

Why the levels converge smoothly enough for this: gmsh's meshes of two levels are not nested, and
where a curved face or a sharp re-entrant edge is meshed at the far size, where its facets fall
changes from one level to the next; on the STEP part that moved the gauge strain by 0.1–0.6 %
between levels in no order (and left the stiffness 1–3 % high). The size field therefore resolves
curvature (meshing.CURVATURE_ELEMENTS per turn) and re-entrant edges (meshing.reentrant_edges),
both scaled with the level. ``tests/test_fem_reference.py`` checks the estimate against
references on five geometries (levels.json: the measured ratios and what is not met).
"""

from __future__ import annotations

import math
import sys

import numpy as np

from userio.errors import InputError

#: figure → nominal convergence order per element order k: a strain reading ~ h^k; the stiffness
#: (an energy) ~ h^(2λ) whatever k, λ ≈ 0.5 the singular exponent at the edges where a clamped or
#: rigidly coupled face meets a free one (every flexure has them; on the paper disc it still falls
#: by 0.24 % from h × 1/√2 to h × 0.42)
FIGURES = {
    "gauge_strain_per_Nm": lambda k: k,
    "sensitivity_mV_per_V_per_Nm": lambda k: k,
    "torsional_stiffness_Nm_per_rad": lambda k: 1.0,
    "safety_factor": lambda k: k,
}
#: figures that ``rtol`` refines (the peak stress behind the safety factor may be singular)
RTOL_FIGURES = ("gauge_strain_per_Nm", "torsional_stiffness_Nm_per_rad")
#: written as powers of 2 (2 ** -0.5, not 1 / √2: they differ in the last bit, and gmsh then makes a
#: different mesh, 50190 instead of 49881 DOFs on the STEP part: tests/data/fem_reference/levels.json)
FACTORS = (2.0 ** 0.5, 1.0, 2.0 ** -0.5)
#: P1 locks in bending: its levels are pre-asymptotic and their changes understate the error
#: (paper disc, default levels: stiffness 18 % above P2's limit with an estimate of 12.5 %, observed
#: order 1.30 from changes of 118 and 75 N·m/rad while the errors fell only from 508 to 315)
P1_WARNING = ("order 1 (linear tetrahedra) is too stiff in bending until many elements span the thickness: its "
              "figures are biased (stiffness high, strains low) by more than the level-to-level error estimate "
              "may show; use order 2 for numbers")
#: a level enters the estimate only with at least this many elements across the gauge grid
MIN_GAUGE_ELEMENTS = 1.0
MAX_DOFS = 2_000_000
P_RANGE = (0.5, 4.0)
#: figure → slowest asymptotic order per element order k (module docstring): h^(2λ) ≥ h for P2's
#: strain, sensitivity and stiffness; none (P_RANGE's floor) for P1 (locking: pre-asymptotic
#: levels) and for the safety factor (the peak stress may diverge at a sharp edge)
MIN_ORDER = {
    "gauge_strain_per_Nm": lambda k: 1.0 if k >= 2 else P_RANGE[0],
    "sensitivity_mV_per_V_per_Nm": lambda k: 1.0 if k >= 2 else P_RANGE[0],
    "torsional_stiffness_Nm_per_rad": lambda k: 1.0 if k >= 2 else P_RANGE[0],
    "safety_factor": lambda k: P_RANGE[0],
}


def observed_order(h: np.ndarray, q: np.ndarray) -> float:
    """p solving (q1 − q2)/(q2 − q3) = (h1^p − h2^p)/(h2^p − h3^p) by bisection on P_RANGE (clipped);
    NaN if the changes have opposite signs (oscillatory)."""
    d12, d23 = q[0] - q[1], q[1] - q[2]
    if d23 == 0.0:
        return P_RANGE[1]
    ratio = d12 / d23
    if ratio <= 0:
        return math.nan
    g = lambda p: (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - ratio  # noqa: E731 (increasing in p)
    lo, hi = P_RANGE
    if g(lo) >= 0:
        return lo
    if g(hi) <= 0:
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def richardson(h, dofs, values, nominal_order: float, min_order: float = P_RANGE[0]) -> tuple[float, float, str]:
    """(error estimate of values[-1] (absolute), observed order, method) from levels of size ``h``;
    the order used is the observed one within [``min_order``, ``nominal_order``]."""
    h = np.asarray(h, float)
    dofs = np.asarray(dofs, float)
    q = np.asarray(values, float)
    if len(q) < 2 or not np.all(np.isfinite(q)):
        return math.nan, math.nan, "not estimated (fewer than two finite levels)"
    if len(q) == 2:
        p = float(nominal_order)
        e = 3.0 * abs(q[1] - q[0]) / ((h[0] / h[1]) ** p - 1.0)
        return e, p, (f"Richardson/GCI from 2 mesh levels ({int(dofs[0])}, {int(dofs[1])} dofs), "
                      f"nominal order {p:g}, safety factor 3; a bound, not 1σ")
    h, q = h[-3:], q[-3:]
    p = observed_order(h, q)
    levels = ", ".join(str(int(n)) for n in dofs[-3:])
    if math.isnan(p):
        e = 1.25 * max(abs(q[0] - q[1]), abs(q[1] - q[2]))
        return e, p, (f"oscillatory convergence over 3 mesh levels ({levels} dofs): 1.25 × the largest "
                      "change; a bound, not 1σ")
    used = min(max(p, float(min_order)), float(nominal_order))
    last = abs(q[2] - q[1])
    if p > used:        # the last change is smaller than theory says: take the one the first implies
        last = max(last, abs(q[0] - q[1]) * (h[1] ** used - h[2] ** used) / (h[0] ** used - h[1] ** used))
    e = 1.25 * last / ((h[1] / h[2]) ** used - 1.0)
    capped = (f", used at the nominal {used:g} (faster than theory is not trusted: the last change is "
              "taken as the larger of the one seen and the one the first implies at that order)") if p > used else ""
    if p < used:
        capped = (f", used at {used:g}, the slowest asymptotic rate of this figure (λ ≥ ½ at every singular "
                  "edge: a slower observed order is the scatter of non-nested meshes)")
    return e, p, (f"Richardson/GCI from 3 mesh levels ({levels} dofs), observed order {p:.2f}{capped}, "
                  "safety factor 1.25; a bound, not 1σ")


def usable_levels(levels: list[dict]) -> tuple[list[dict], str]:
    """The levels with ≥ MIN_GAUGE_ELEMENTS elements across the gauge grid (``gauge_elements``),
    and a note naming the ones left out ('' if none)."""
    keep = [lv for lv in levels if lv.get("gauge_elements", math.inf) >= MIN_GAUGE_ELEMENTS]
    out = [lv for lv in levels if lv not in keep]
    if not out:
        return keep, ""
    return keep, ("; left out: " + ", ".join(f"h × {lv['h_factor']:.3g} ({lv['gauge_elements']:.2f} elements "
                                             "across a gauge grid)" for lv in out))


def estimate_from_levels(levels: list[dict], key: str, order: int) -> tuple[float, float, str]:
    """``richardson`` on the usable levels (``level_record``s) for figure ``key`` of elements of
    ``order``: (error estimate of the finest level, observed order, method incl. levels left out)."""
    used, note = usable_levels(levels)
    e, p, method = richardson([lv["h_factor"] for lv in used], [lv["dofs"] for lv in used],
                              [lv[key] for lv in used], FIGURES[key](order), MIN_ORDER[key](order))
    return e, p, method + note


def _attach(res: dict, levels: list[dict], order: int) -> dict:
    """Error keys beside every figure of ``res`` (the finest level), from the usable levels."""
    orders = {}
    for key in FIGURES:
        e, p, method = estimate_from_levels(levels, key, order)
        res[f"{key}_error_estimate"] = float(e)
        res[f"{key}_error_method"] = method
        orders[key] = None if math.isnan(p) else float(p)
    res["discretization_levels"] = levels
    res["discretization_observed_order"] = orders
    from flexure.slivers import widen

    widen(res, levels, FIGURES)          # slivers at a level: ± at least the levels' spread
    return res


def level_record(design, res: dict, h_factor: float) -> dict:
    """One mesh level as the estimate uses it: its size factor, DOFs, time, elements across the
    narrowest gauge grid side (``usable_levels``) and the FIGURES."""
    side = min(min(g.length_m, g.width_m) for g in design.gauges)
    return {"h_factor": float(h_factor), "dofs": int(res["dofs"]), "total_s": res["total_s"],
            "gauge_elements": float(side / res["mesh"]["h_gauge_m"]), **{k: res[k] for k in FIGURES},
            "n_slivers_10deg": int(res["mesh"].get("n_slivers_10deg", 0))}


def relative_error(res: dict, key: str) -> float:
    v = res.get(key)
    e = res.get(f"{key}_error_estimate", math.nan)
    return abs(e / v) if v not in (None, 0) and math.isfinite(v) else math.nan


#: the last ``rtol`` level is aimed at this fraction of ``max_dofs`` (the DOF prediction is a fit)
FILL = 0.9
#: ... and is made only if it is at least this much finer than the level before (h ratio): closer
#: levels differ by little more than the scatter of non-nested meshes (0.02–0.05 % on a strain)
MIN_LAST_RATIO = 2.0 ** 0.25


def next_level(levels: list[dict], max_dofs: int) -> tuple[float | None, int, bool]:
    """The next ``rtol`` level after ``levels`` (coarsest first): (h factor or None, predicted DOFs,
    whether it is the last one). DOFs are predicted by the power law through the last two levels,

        n(f) = n_k · (f_k / f)^s,   s = ln(n_k / n_(k−1)) / ln(f_(k−1) / f_k),  clipped to [1, 3]

    (graded meshes grow slower than f^−3: s = 1.6–2.2 on the reference parts). h × 1/√2 if
    n ≤ max_dofs; else the level aimed at FILL · max_dofs, if it is MIN_LAST_RATIO finer than the
    last (the spacing of levels need not be uniform: ``observed_order`` takes any h); else None."""
    n_k, f_k = levels[-1]["dofs"], levels[-1]["h_factor"]
    s = 3.0
    if len(levels) >= 2 and levels[-2]["h_factor"] > f_k and levels[-2]["dofs"] > 0:
        s = math.log(n_k / levels[-2]["dofs"]) / math.log(levels[-2]["h_factor"] / f_k)
        s = min(max(s, 1.0), 3.0) if math.isfinite(s) else 3.0
    f = f_k / math.sqrt(2.0)
    predicted = int(n_k * (f_k / f) ** s)
    if predicted <= max_dofs:
        return f, predicted, False
    f_fit = f_k * (n_k / (FILL * max_dofs)) ** (1.0 / s)
    if f_k / f_fit >= MIN_LAST_RATIO:
        return f_fit, int(FILL * max_dofs), True
    return None, predicted, True


def analyze_with_error(design, size: str | None = None, order: int | None = None, rtol: float | None = None,
                       max_dofs: int = MAX_DOFS, progress: bool = False, factors=FACTORS,
                       max_elements: float | None = None):
    """``analysis.analyze`` on the levels ``factors`` (coarsest first; the last is the answer),
    then, with ``rtol``, on finer levels (``next_level``: × 1/√2 each, the last one fitted under
    ``max_dofs``) until the relative error estimates of RTOL_FIGURES are ≤ rtol, or no finer level
    fits under ``max_dofs`` or one is refused by the mesh-cost check (a warning says so; the levels
    solved are kept).
    → (results of the finest level with ``<figure>_error_estimate``/``_error_method``, Fields)."""
    from flexure.analysis import analyze

    if rtol is not None and not (math.isfinite(rtol) and 0 < rtol < 1):
        raise InputError(f"--rtol: must be in (0, 1), got {rtol!r}")
    levels, res, fields = [], None, None
    factors = list(factors)

    def run(f):
        nonlocal res, fields
        if progress:
            print(f"flexure: mesh level h × {f:.3g}", file=sys.stderr)
        res, fields = analyze(design, size, order, progress=progress, h_factor=f, max_elements=max_elements)
        levels.append(level_record(design, res, f))

    for f in factors:
        run(f)
    order_used = int(res["order"])
    _attach(res, levels, order_used)
    warnings = []
    if rtol is not None:
        def not_reached(why: str) -> str:
            return (f"--rtol {rtol:g} not reached: error estimate {worst:.2%} at "
                    f"{levels[-1]['dofs']} dofs; the next level {why}")

        fitted = False
        while (worst := max(relative_error(res, k) for k in RTOL_FIGURES)) > rtol:
            if fitted:
                warnings.append(not_reached(f"would exceed --max-dofs {max_dofs} (the last one was made to fit under it)"))
                break
            f, predicted, fitted = next_level(levels, max_dofs)
            if f is None:
                warnings.append(not_reached(f"(~{predicted} dofs) exceeds --max-dofs {max_dofs}"))
                break
            try:
                run(f)
            except InputError as exc:       # a finer level refused (mesh cost): keep what is solved
                warnings.append(not_reached(f"(h × {f:.3g}) was refused: {exc}"))
                break
            _attach(res, levels, order_used)
        res["rtol"] = rtol
        for k in FIGURES:
            if relative_error(res, k) > rtol and not any(w.startswith(f"{k}:") for w in warnings):
                warnings.append(f"{k}: discretization error estimate {relative_error(res, k):.2%} exceeds "
                                f"--rtol {rtol:g}")
    if order_used == 1:
        warnings.append(P1_WARNING)
    imb = res.get("gauge_arm_imbalance", math.nan)
    if len(design.gauges) == 4 and math.isfinite(imb) and imb > 0.02:
        warnings.append(f"gauge arms differ by {imb:.1%} under torque: a symmetric layout should read "
                        "equal |strain| on every arm (mesh not converged at the gauges, or asymmetric)")
    res["warnings"] = list(res["warnings"]) + warnings
    res["total_s"] = float(sum(lv["total_s"] for lv in levels))
    return res, fields


#: the error method a design is analysed with unless one is asked for (``analyze_design``)
DEFAULT_METHOD = "adaptive"


def analyze_design(design, size: str | None = None, order: int | None = None, rtol: float | None = None,
                   method: str | None = None, max_dofs: int | None = None, max_memory_gb: float | None = None,
                   progress: bool = False, max_elements: float | None = None, max_seconds: float | None = None):
    """The analysis with its discretisation error estimates, by ``method`` (default DEFAULT_METHOD):
    "adaptive" (goal-oriented estimates on nested, locally refined meshes, flexure.adaptive) or
    "levels" (this module's Richardson over gmsh mesh levels, the cross-check). P1 (order 1) always
    uses the levels (the refinement works on P2 meshes), and says so; ``max_seconds`` (the adaptive
    refinement's time budget) is refused there. → (results, Fields)."""
    method = method or DEFAULT_METHOD
    eff_order = order or design.order
    if max_seconds is not None and (method != "adaptive" or eff_order != 2):
        raise InputError("--max-seconds: a budget of the adaptive refinement (order 2); the levels have none")
    if method == "adaptive" and eff_order != 2:
        res, fields = analyze_with_error(design, size, order, rtol, max_dofs=max_dofs or MAX_DOFS,
                                         progress=progress, max_elements=max_elements)
        res["warnings"] = list(res["warnings"]) + [
            "order 1: the error estimate is the levels' (Richardson); adaptive refinement works on order 2"]
        return res, fields
    if method == "adaptive":
        from flexure import adaptive

        return adaptive.analyze_adaptive(design, size, rtol=rtol, max_dofs=max_dofs or adaptive.MAX_DOFS,
                                         max_memory_gb=max_memory_gb or adaptive.MAX_MEMORY_GB,
                                         progress=progress, max_elements=max_elements, max_seconds=max_seconds)
    if method != "levels":
        raise InputError(f"error method must be 'adaptive' or 'levels', got {method!r}")
    res, fields = analyze_with_error(design, size, order, rtol, max_dofs=max_dofs or MAX_DOFS, progress=progress,
                                     max_elements=max_elements)
    res["error_method"] = "levels"
    return res, fields


def design_figures(path, overrides: dict | None = None, size: str | None = None, order: int | None = None,
                   rtol: float | None = None, method: str | None = None) -> dict:
    """For the pipeline: a design file (+ overrides) → gauge strain per N·m, torsional stiffness,
    safety factor, sensitivity, each with ``_error_estimate``/``_error_method``; the minimum
    detectable torque (1σ bridge noise; its relative error is the gauge strain's) and the largest
    cross-talk (% of rated output); and warnings."""
    from flexure.design import load_design

    res, _ = analyze_design(load_design(path, overrides), size, order, rtol, method)
    keys = [k for f in FIGURES for k in (f, f"{f}_error_estimate", f"{f}_error_method")]
    flagged = {"nan_reason": res["nan_reason"]} if res.get("nan_reason") else {}
    extra = {}
    mdt = res.get("min_detectable_torque_Nm")
    if mdt is not None:
        rel = res["gauge_strain_per_Nm_error_estimate"] / abs(res["gauge_strain_per_Nm"]) \
            if res.get("gauge_strain_per_Nm") else math.nan
        extra.update(min_detectable_torque_Nm=mdt, min_detectable_torque_Nm_error_estimate=mdt * rel,
                     min_detectable_torque_Nm_error_method="the gauge strain's relative error "
                     "(the minimum torque is the bridge noise over the strain per N·m)")
    xt = [abs(v) for v in (res.get("crosstalk_percent") or {}).values() if v is not None and math.isfinite(v)]
    if xt:
        extra["crosstalk_max_percent"] = max(xt)
    return {**{k: res[k] for k in keys}, **extra, "dofs": res["dofs"], "warnings": list(res["warnings"]),
            **flagged}
