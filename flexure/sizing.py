"""The mesh size field and what it costs: ``SizeField`` (h(x), finer at the gauges and toward sharp
re-entrant edges), ``edge_size`` (the √d grading at such an edge), and the element-count estimate
that refuses a hopeless mesh before any meshing (``estimate_elements``, ``check_cost``).

Pure numpy: imported by every mesher (flexure.meshing, flexure.gmsh_mesh) and by the preflight
(flexure.design), so none of them needs another's module for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError


@dataclass
class SizeField:
    """h(x) = clip(h_gauge + grading·(d(x) − r_gauge), h_gauge, h_far), d = distance to the
    nearest gauge centre (in the xy-plane for extrusions); on curved edges and faces of a CAD
    solid (gmsh) also h ≤ 2πR / ``curvature_elements`` (R the local radius of curvature)."""

    h_far: float
    h_gauge: float
    centres: np.ndarray          # (g, 2 or 3)
    r_gauge: float
    grading: float = 0.35
    curvature_elements: float = 0.0
    #: sharp re-entrant edges (k, 2, 3) and their sizes h_edge (k,): h ≤ ``edge_size`` (gmsh only,
    #: like the curvature term)
    edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    h_edge: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: local sizes (k, 4: x, y, z, h; m): h ≤ h_k + grading · distance (gmsh only; an STL's curved
    #: faces, flexure.stl_remesh.curvature_spots)
    spots: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, float)
        if len(self.centres) == 0:
            return np.full(len(xy), self.h_far)
        c = self.centres[:, : xy.shape[1]]
        d = np.sqrt(((xy[:, None, :] - c[None]) ** 2).sum(-1)).min(1)
        return np.clip(self.h_gauge + self.grading * (d - self.r_gauge), self.h_gauge, self.h_far)


#: the size at a re-entrant edge is h_edge / EDGE_REFINEMENT, graded as √d up to h_edge at d = 2 h_edge
EDGE_REFINEMENT = 4.0


def edge_size(h_edge, d, grading: float, r_plateau: float):
    """Size at distance d from a sharp re-entrant edge of size h_edge (arrays broadcast):

        h = min(h_edge + g·max(d − r, 0),  max(h_edge / 4, h_edge·√(d / 2h_edge)))

    The displacement there goes as d^λ (λ ≈ 0.54 at a 90° notch): a mesh graded as h ~ √d
    resolves it about as well as the smooth field elsewhere (Babuška, Kellogg & Pitkäranta 1979:
    h ~ d^(1−μ), μ < λ); the floor h_edge / 4 keeps the grading self-similar from level to level,
    so the singular part still converges as h^(2λ), with a far smaller constant. On the thick disc
    (sharp spoke roots) the stiffness at h × 1/√2 went from 3278 to 3188 N·m/rad (its limit then:
    3165 ± 10; with isoparametric P2 today 3194 against 3164 ± 13, tests/data/fem_reference/levels.json),
    for 1.5× the DOFs; before the last change of
    gmsh's optimiser (VOLUME_OPTIONS), floors of h_edge / 2, / 4, / 8 gave 3204, 3186, 3187. The same grading at the supports' edges (bolt-hole
    walls, the bore) made it no better (3191) for 1.9× the DOFs, so it is not applied there."""
    h_edge, d = np.asarray(h_edge, float), np.asarray(d, float)
    graded = np.maximum(h_edge / EDGE_REFINEMENT, h_edge * np.sqrt(d / (2.0 * h_edge)))
    return np.minimum(h_edge + grading * np.maximum(d - r_plateau, 0.0), graded)



#: refuse a mesh estimated above this many tetrahedra before meshing (``--max-elements``)
MAX_ELEMENTS = 500_000
#: bytes per P2 tetrahedron for the memory figure of the refusal (assembly + AMG, measured order)
BYTES_PER_ELEMENT = 12_000


def estimate_elements(field: SizeField, volume_m3: float, thickness_m: float, walls=()) -> float:
    """Tetrahedra a mesh of ``field`` will have: the sum of ``estimate_parts``."""
    return float(sum(estimate_parts(field, volume_m3, thickness_m, walls).values()))


def estimate_parts(field: SizeField, volume_m3: float, thickness_m: float, walls=()) -> dict:
    """Tetrahedra a mesh of ``field`` will have, by what makes them: N = ∫_V dV / v(h(x)),
    v(h) = h³/(6√2) (regular tet), h ≤ t = ``thickness_m`` (the part's own thickness 2V/A: no
    element is larger than the part).

    - "volume": h = h_far over the whole volume, V c / h_far³ (c = 6√2);
    - "gauges": each gauge adds the integral over the ball where h(d) < h_far (d = distance to its
      centre), of which the part holds the fraction φ(d) = ½ for d ≤ t (a gauge sits on a face: a
      half ball) and t/(2d) beyond (a plate of thickness t: the band of the sphere inside it);
    - "edges": each re-entrant edge the same over the cylinder around it (¾ inside);
    - one entry per key of ``walls`` — (key, R, height, arc fraction α, material outside the circle?)
      — for curved faces meshed at h_c = 2πR / curvature_elements (gmsh's curvature sizing):
      height × ∫₀^S α 2π(R ± s) c (h(s)⁻³ − h_far⁻³) ds, h(s) = h_c + g s, S = (h_far − h_c)/g.
      A bolt hole's wall 4 m tall is millions of elements that the volume term never sees.

    Measured against the meshes made: tests/test_mesh_cost.py (within 2×)."""
    c = 6.0 * math.sqrt(2.0)
    t = float(thickness_m)
    h_far = min(field.h_far, t)
    parts = {"volume": volume_m3 * c / h_far ** 3, "gauges": 0.0, "edges": 0.0}
    g = field.grading
    for key, R, height, alpha, outside in walls:
        if field.curvature_elements <= 0 or R <= 0:
            continue
        hc = 2.0 * math.pi * R / field.curvature_elements
        if hc >= h_far:
            continue
        s = np.linspace(0.0, (h_far - hc) / g if outside else min((h_far - hc) / g, R), 801)
        shell = alpha * 2.0 * np.pi * np.maximum(R + s if outside else R - s, 0.0)
        f = shell * c * (1.0 / (hc + g * s) ** 3 - 1.0 / h_far ** 3)
        parts[key] = parts.get(key, 0.0) + float(height * np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(s)))
    if len(field.centres) == 0 or field.h_gauge >= h_far:
        return parts
    R = field.r_gauge + (h_far - field.h_gauge) / field.grading
    d = np.linspace(0.0, R, 2001)[1:]
    h = np.minimum(np.clip(field.h_gauge + field.grading * (d - field.r_gauge), field.h_gauge, field.h_far), h_far)
    phi = np.where(d <= t, 0.5, t / (2.0 * d))
    ball = 4.0 * np.pi * d ** 2 * phi * c * (1.0 / h ** 3 - 1.0 / h_far ** 3)
    parts["gauges"] = float(len(field.centres) * np.sum(0.5 * (ball[1:] + ball[:-1]) * np.diff(d)))
    for (a, b), he in zip(np.asarray(field.edges).reshape(-1, 2, 3), np.asarray(field.h_edge)):
        # a re-entrant edge: the graded cylinder around it, 3/4 of it inside (a 90° notch)
        if he >= h_far:
            continue
        rho = np.geomspace(he * 1e-3, field.r_gauge + (h_far - he) / field.grading, 401)
        h = np.minimum(edge_size(he, rho, field.grading, field.r_gauge), h_far)
        band = 0.75 * 2.0 * np.pi * rho * c * (1.0 / h ** 3 - 1.0 / h_far ** 3)
        parts["edges"] += float(np.linalg.norm(b - a)) * np.sum(0.5 * (band[1:] + band[:-1]) * np.diff(rho))
    return parts


def check_cost(field: SizeField, volume_m3: float, area_m2: float, max_elements: float,
               where: str = "mesh") -> float:
    """Refuse up front (InputError) a mesh estimated above ``max_elements``; → the estimate."""
    n = estimate_elements(field, volume_m3, 2 * volume_m3 / area_m2) if area_m2 > 0 else math.inf
    if not np.isfinite(n) or n > max_elements:
        raise InputError(f"{where}: the mesh would have ~{n:.3g} tetrahedra (~{n * BYTES_PER_ELEMENT / 1e9:.3g} GB "
                         f"for P2), above --max-elements {max_elements:.3g}; check the dimensions "
                         "(a feature far thinner or thicker than the gauges?) or raise --max-elements")
    return n


