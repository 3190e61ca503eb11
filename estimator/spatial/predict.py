"""What localization error will these sensors give on this robot? The 3-D error map.

At a posture, for points all over every link's collision surface, a force of the given magnitude
pushing straight in (F = −|F| n) gives the settled residual r = A_b [F; p × F]. The localizer
(estimator.spatial.localize) is differentiated with respect to r by central differences on the
rows that are equations, J = ∂p̂/∂r, and the residual's no-contact covariance R of the declared
sensors (estimator.spatial.noise) propagates to the point: Σ_p = J R Jᵀ, error = √tr Σ_p (the
RMS distance of a per-sample estimate from the true point). NaN where the exact residual is
refused (grazing, ambiguous between links): no confident answer there at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.spatial import localize as loc
from estimator.spatial.geometry import body_surfaces
from estimator.spatial.model import columns, moves
from estimator.spatial.noise import residual_covariance
from estimator.spatial.observer import used_rows
from estimator.spatial.tree import body_poses


@dataclass
class SurfaceMap:
    link: str                    # URDF link of the solid
    body: int
    vertices: np.ndarray         # (V, 3) body frame
    faces: np.ndarray            # (F, 3)
    error_m: np.ndarray          # (V,) RMS position error, NaN where refused
    reason: np.ndarray           # (V,) reason of the exact answer


def solid_mesh(shape, resolution: int = 24):
    """A triangle mesh of a collision solid in its body frame (trimesh primitives)."""
    import trimesh

    if shape.kind == "box":
        m = trimesh.creation.box(extents=shape.size)
        m = m.subdivide().subdivide()
    elif shape.kind == "cylinder":
        m = trimesh.creation.cylinder(radius=shape.size[0], height=shape.size[1], sections=resolution)
        m = m.subdivide_to_size(shape.size[1] / 8)
    elif shape.kind == "capsule":
        m = trimesh.creation.capsule(radius=shape.size[0], height=shape.size[1], count=[resolution, resolution])
    elif shape.kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=2, radius=shape.size[0])
    else:
        m = trimesh.load(shape.mesh_path, force="mesh")
        m.apply_scale(np.asarray(shape.size))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = shape.rotation, shape.origin
    m.apply_transform(T)
    return m


def surface_samples(shape, mesh):
    """The mesh's vertices snapped onto the exact solid, with its outward normals there (body
    frame): a subdivided facet's vertices lie inside a round solid, and a facet normal is not
    the solid's."""
    V = (np.asarray(mesh.vertices) - shape.origin) @ shape.rotation      # local frame
    N = np.asarray(mesh.vertex_normals) @ shape.rotation
    if shape.kind == "sphere":
        N = V / np.linalg.norm(V, axis=1, keepdims=True)
        V = N * shape.size[0]
    elif shape.kind in ("cylinder", "capsule"):
        r, L = shape.size
        z = np.clip(V[:, 2], -L / 2, L / 2)
        radial = V - np.c_[np.zeros((len(V), 2)), z]
        rn = np.linalg.norm(radial, axis=1)
        if shape.kind == "capsule":
            N = radial / rn[:, None]
            V = np.c_[np.zeros((len(V), 2)), z] + r * N
        else:
            side = np.abs(V[:, 2]) < L / 2 - 1e-9 * L
            xy = V[:, :2] / np.maximum(np.hypot(V[:, 0], V[:, 1]), 1e-300)[:, None]
            V[side, :2] = r * xy[side]
            N[side] = np.c_[xy[side], np.zeros(side.sum())]
    return V @ shape.rotation.T + shape.origin, N @ shape.rotation.T


def point_errors(model, surfaces, q, body, points_body, forces_world, R, h=1e-4):
    """RMS position error √tr(J R Jᵀ) (V,) and the exact answer's reason (V,) of contacts at
    ``points_body`` (V, 3) on ``body`` with forces (V, 3, world) at posture q (nq,)."""
    q = np.asarray(q, float)[None]
    rows = used_rows(model)
    Linv = np.linalg.inv(np.linalg.cholesky(R))
    S, *_ = columns(model.tree, q)
    Rb, pb, _, _ = body_poses(model.tree, q, relative=True)
    pw = pb[0, body] + np.asarray(points_body, float) @ Rb[0, body].T
    F = np.asarray(forces_world, float)
    W = np.concatenate([F, np.cross(pw, F)], axis=1)
    r0 = (W @ S[0].T) * moves(model.tree)[:, body]                      # (V, nv)
    nu, V = len(rows), len(F)
    pert = np.zeros((2 * nu + 1, model.n_v))
    pert[1:nu + 1, rows] = np.eye(nu) * h
    pert[nu + 1:, rows] = -np.eye(nu) * h
    rr = (r0[:, None, :] + pert[None]).reshape(-1, model.n_v)
    res = loc.localize(model, surfaces, np.repeat(q, len(rr), axis=0), rr, Linv)
    pts = res.point_body.reshape(V, 2 * nu + 1, 3)
    reason = res.reason.reshape(V, 2 * nu + 1)
    J = (pts[:, 1:nu + 1] - pts[:, nu + 1:]) / (2 * h)                    # (V, nu, 3)
    err = np.sqrt(np.trace(np.einsum("vik,ij,vjl->vkl", J, R, J), axis1=1, axis2=2))
    bad = (reason != loc.OK).any(axis=1)
    return np.where(bad, np.nan, err), reason[:, 0]


def error_map(model, q, noise, magnitude_N=5.0, gain_per_s=100.0, dt_s=1e-3, h=1e-4,
              resolution: int = 24) -> list[SurfaceMap]:
    """One SurfaceMap per collision solid at posture q (nq,) (module doc)."""
    q = np.asarray(q, float)
    surfaces = body_surfaces(model.robot, model.tree)
    R = residual_covariance(model, q[None], np.zeros((1, model.n_v)), noise, gain_per_s, dt_s)[0]
    Rb = body_poses(model.tree, q[None], relative=True)[0][0]
    out = []
    for surf in surfaces:
        b = surf.body
        for link, shape in surf.solids:
            mesh = solid_mesh(shape, resolution)
            V, N = surface_samples(shape, mesh)
            err, reason = point_errors(model, surfaces, q, b, V, -magnitude_N * (N @ Rb[b].T), R, h)
            out.append(SurfaceMap(link, b, V, np.asarray(mesh.faces), err, reason))
    return out


def summarize(maps) -> dict:
    """Per link: median / max of the RMS error over its surface points, the refused fraction."""
    out = {}
    for m in maps:
        e = m.error_m
        ok = np.isfinite(e)
        out[m.link] = {"points": int(len(e)), "refused_fraction": float(1 - ok.mean()),
                       "position_rms_median_m": float(np.median(e[ok])) if ok.any() else None,
                       "position_rms_max_m": float(e[ok].max()) if ok.any() else None}
    return out
