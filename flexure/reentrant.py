"""Sharp re-entrant edges of a part, from its mesh's boundary: where the enriched space saturates poorly.

Two boundary faces sharing an edge, outward normals n₁, n₂, turn by φ = arccos(n₁·n₂); the solid's
interior angle there is ω = π + φ where the edge is concave (the second face rises on the outward side
of the first: (c₂ − a)·n₁ > 0, c₂ its vertex off the edge), else π − φ. An edge with ω ≥ SHARP_DEG is a
sharp re-entrant edge: its field is singular, u ~ r^λ, λ < 1 (λ ≥ ½, the crack limit ω → 2π), and the
saturation ratio of P3 over P2 there is about (2/3)^(4λ) (flexure.saturation). Below SHARP_DEG are the
facets of curved concave faces (a bore resolved at 12 elements per turn turns 30° per edge, ω = 210°;
an STL's polygon of 192 sides 2°) and fillets: their field is smooth at the mesh's scale.
"""

from __future__ import annotations

import numpy as np

#: interior angle (degrees) from which a concave boundary edge counts as sharp
SHARP_DEG = 240.0


def fold_angles_deg(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The interior dihedral angle ω (degrees) of a closed, outward-oriented triangulation (points
    (n,3), faces (k,3)) at each edge shared by exactly two faces (module docstring) → (edges (m,2)
    node pairs, ω (m,)); edges of one face or of three and more are skipped."""
    faces = np.asarray(faces)[:, :3].astype(np.int64)
    x = np.asarray(points, float)
    n = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a = faces[:, [0, 1, 2]].ravel()
    b = faces[:, [1, 2, 0]].ravel()
    c = faces[:, [2, 0, 1]].ravel()                 # the face's vertex off the edge (a, b)
    f = np.repeat(np.arange(len(faces)), 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo))
    lo, hi, c, f = lo[order], hi[order], c[order], f[order]
    same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1])
    first = np.flatnonzero(same)
    # exactly two faces: the pair (i, i+1) not part of a run of three or more
    run3 = np.zeros(len(same), bool)
    run3[1:] |= same[1:] & same[:-1]
    run3[:-1] |= same[1:] & same[:-1]
    first = first[~run3[first]]
    f1, f2, c2 = f[first], f[first + 1], c[first + 1]
    cos = np.clip(np.einsum("ij,ij->i", n[f1], n[f2]), -1.0, 1.0)
    phi = np.degrees(np.arccos(cos))
    concave = np.einsum("ij,ij->i", x[c2] - x[lo[first]], n[f1]) > 1e-12 * np.ptp(x, axis=0).max()
    return np.stack([lo[first], hi[first]], axis=1), np.where(concave, 180.0 + phi, 180.0 - phi)


def max_interior_angle_deg(mesh) -> float:
    """The largest interior dihedral angle ω (degrees) of the solid over its boundary's edges
    (``fold_angles_deg``; below 180 where every edge is convex); 180 where no edge has two faces."""
    _, omega = fold_angles_deg(mesh.points, mesh.boundary_faces())
    return float(omega.max()) if len(omega) else 180.0


def has_sharp_reentrant_edge(mesh) -> bool:
    """Whether the part has an edge with interior angle ≥ SHARP_DEG (module docstring)."""
    return max_interior_angle_deg(mesh) >= SHARP_DEG
