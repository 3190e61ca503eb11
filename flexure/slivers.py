"""Sliver tetrahedra: the warning that says what they are, and the error estimate they widen.

A sliver is a tetrahedron with a dihedral angle below SLIVER_DEG = 10° (four nearly coplanar
vertices, or a needle). Its element stiffness is ill-conditioned (the shape functions' gradients
grow as 1/sin θ), its strains are poor, and where slivers sit differs from one mesh level to the
next (gmsh's meshes of two levels are not nested): the levels then scatter in no order, and a
Richardson estimate that reads that scatter as convergence can be tight while the answer is off
(the issue's designer STL: 102 slivers, a 0.1° one, a safety factor of 6.73 ± 30 % where one level
read 7.55). So on a run where any level has slivers:

    e_Q ← max(e_Q, max_i |Q_i − Q_answer|)          (i over the mesh levels)

every figure's ± is at least the spread of its levels around the answer, the level with slivers
among them (``widen``); and the warning names how many elements, the worst angle, what it means
and what to do (``annotate``).
"""

from __future__ import annotations

import math

import numpy as np

SLIVER_DEG = 10.0
KEY = "n_slivers_10deg"
WORST = "min_dihedral_deg"


def sliver_count(mesh) -> tuple[int, float]:
    """(tetrahedra with a dihedral angle below SLIVER_DEG, the smallest dihedral angle in degrees)."""
    from flexure.mesh import element_shape_metrics

    dmin = element_shape_metrics(mesh.points, mesh.corner_tets)["dihedral_deg"].min(axis=1)
    return int(np.count_nonzero(dmin < SLIVER_DEG)), float(dmin.min())


def explain(n: int, total: int, worst_deg: float, attempts: list | None = None) -> str:
    """The sliver warning, one line: how many, how bad, after how many meshing attempts (gmsh's
    record, flexure.gmsh_mesh._session), what it means, what to do."""
    tried = ""
    if attempts:
        ran = [a for a in attempts if "min_dihedral_deg" in a]
        tried = (f" after {len(attempts)} meshing attempt{'s' if len(attempts) > 1 else ''} ("
                 + ", ".join(f"{a['strategy']}: {a['min_dihedral_deg']:.2g}°" for a in ran)
                 + (f"; {len(attempts) - len(ran)} failed" if len(ran) < len(attempts) else "") + ")")
    return (f"sliver_elements: {n} of {total} tetrahedra have a dihedral angle below {SLIVER_DEG:g}° (worst "
            f"{worst_deg:.2g}°{tried}): such flat elements are ill-conditioned and the strains and stresses "
            "around them unreliable (the levels' estimate widens every figure's ± to the spread of its mesh "
            "levels; each ±'s method says what it covers); remove thin walls and long, needle-like triangles "
            "from the part's surface (or try --size medium)")


def annotate(warnings: list[str], mesh, report: dict) -> list[str]:
    """Count the slivers of ``mesh`` into ``report`` (KEY) and replace the solver's bare
    ``sliver_elements`` (flexure.solve: many below 5°, or one below 1°) by ``explain``'s line,
    raised for any sliver below SLIVER_DEG. → the new warnings list."""
    n, worst = sliver_count(mesh)
    report[KEY] = n
    out = [w for w in warnings if w != "sliver_elements"]
    if n:
        out.append(explain(n, int(len(mesh.corner_tets)), worst, report.get("mesh_attempts")))
    return out


def widen(res: dict, levels: list[dict], figures) -> None:
    """On a run with slivers at any level (``levels``: flexure.convergence.level_record, with
    KEY), each of ``figures``' error estimates in ``res`` becomes at least the spread of its
    levels around the answer (module docstring), its method saying so."""
    bad = [lv for lv in levels if lv.get(KEY, 0) > 0]
    if not bad or len(levels) < 2:
        return
    where = ", ".join(f"h × {lv['h_factor']:.3g} ({lv[KEY]} below {SLIVER_DEG:g}°)" for lv in bad)
    for key in figures:
        vals = np.array([lv.get(key, math.nan) for lv in levels], float)
        answer = res.get(key)
        if answer is None or not np.isfinite(answer):
            continue
        spread = float(np.nanmax(np.abs(vals - answer))) if np.isfinite(vals).any() else math.nan
        e = res.get(f"{key}_error_estimate", math.nan)
        if not np.isfinite(spread):
            continue
        widened = not (e is not None and np.isfinite(e) and e >= spread)
        if widened:
            res[f"{key}_error_estimate"] = spread
        res[f"{key}_error_method"] = (str(res.get(f"{key}_error_method", "")) + "; slivers at " + where + ": "
                                      + ("widened to" if widened else "already covers")
                                      + " the spread of the mesh levels around the answer")
