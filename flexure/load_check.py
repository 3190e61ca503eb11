"""Checks of the loads against the part that need no mesh, run before meshing.

The analysis (flexure.analysis._selections) loads the boundary nodes with r ≤ r_load
(``loads.load_radius_max_mm``) and holds those with r ≥ r_hold (``loads.fixed_radius_min_mm``),
r = √(x² + y²) the distance to the torque axis (the file's z axis). Both sets can be known empty
from the closed surface alone, before any meshing:

    r_max = max over the surface's vertices of r          (r is convex: a triangle's largest r is
                                                           at a vertex)
    r_min = min over its triangles of the distance of their xy-projection to the axis
            (0 if a projection covers the axis, else the nearest edge: segment-to-point distance)

A hold radius above r_max or a load radius below r_min selects no surface at all, whatever the
mesh: refused here (InputError naming the key the user wrote in the design file and the radius
the part reaches), in milliseconds instead of after a level of meshing.
"""

from __future__ import annotations

import numpy as np

from userio.errors import InputError

#: relative tolerance on the radii (of the part's largest extent), as the node selection's
TOL = 1e-6


def axis_distance_range(points: np.ndarray, faces: np.ndarray) -> tuple[float, float]:
    """(r_min, r_max) of a closed triangle surface (m): module docstring."""
    xy = np.asarray(points, float)[:, :2]
    r_max = float(np.hypot(xy[:, 0], xy[:, 1]).max())
    tri = xy[np.asarray(faces, np.int64)]                                    # (m, 3, 2)
    a, b = tri, np.roll(tri, -1, axis=1)                                     # edges a → b
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]                    # sign of the origin per edge
    covers = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    area = np.abs(cross.sum(axis=1))
    if np.any(covers & (area > 0)):
        return 0.0, r_max
    d = b - a
    dd = np.einsum("...i,...i->...", d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.clip(np.where(dd > 0, -np.einsum("...i,...i->...", a, d) / dd, 0.0), 0.0, 1.0)
    nearest = a + s[..., None] * d
    return float(np.hypot(nearest[..., 0], nearest[..., 1]).min()), r_max


def _key(design, key: str, default_from: str) -> str:
    """``loads.KEY = value mm`` as the user wrote it, or the default and where it comes from."""
    value = design.raw.get("loads", {}).get(key)
    if value is not None:
        return f"loads.{key} = {value:g} mm"
    return f"loads.{key} (not set: its default from {default_from})"


def check_loads(design, surface) -> None:
    """Refuse (InputError, one line naming the design file and key) a hold or load radius that
    selects no surface of the part (module docstring). ``surface``: a geometry.Surface (m)."""
    r_min, r_max = axis_distance_range(surface.points, surface.faces)
    tol = TOL * max(float(np.ptp(surface.points, axis=0).max()), 1e-9)
    lo, hi = surface.points[:, :2].min(axis=0), surface.points[:, :2].max(axis=0)
    if np.any(lo > tol) or np.any(hi < -tol):           # the axis misses the part's footprint
        centre = np.round((lo + hi) / 2 * 1e3, 3).tolist()
        raise InputError(f"{design.path}: geometry.file: the part does not surround the torque axis "
                         f"(the file's z axis through its origin): its bounding box is centred at "
                         f"x, y = {centre} mm; draw the part around the axis of the torque it carries")
    if design.fixed != "rim_bolts" and design.fixed_radius_min_m > r_max + tol:
        key = _key(design, "fixed_radius_min_mm", "geometry.outer_radius_mm")
        raise InputError(f"{design.path}: {key} holds the part where r ≥ "
                         f"{design.fixed_radius_min_m * 1e3:g} mm from the torque axis, but the part reaches only "
                         f"r = {r_max * 1e3:.4g} mm: set it below {r_max * 1e3:.4g} mm (the outer face to hold)")
    if design.load_radius_max_m < r_min - tol:
        key = _key(design, "load_radius_max_mm", "geometry.bore_radius_mm")
        raise InputError(f"{design.path}: {key} loads the part where r ≤ "
                         f"{design.load_radius_max_m * 1e3:g} mm from the torque axis, but the part comes no "
                         f"closer than r = {r_min * 1e3:.4g} mm (its bore): set it above {r_min * 1e3:.4g} mm "
                         "(the torque axis is the file's z axis through its origin)")
