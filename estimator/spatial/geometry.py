"""Link surfaces: the URDF collision solids of each body, where a line of action enters them,
points on them (for simulated pokes), and the segment of a body without collision geometry.

A body (estimator.spatial.tree) carries the solids of every URDF link fixed to it (pinocchio
merges fixed links). Lines are p(s) = o + s d with d the unit force direction, in the body frame;
a force pushes INTO the surface where d · n < 0 (n the outward normal): for a convex solid that
is the entry point, the smaller root. For a union of solids the first entry along the line is on
the union's surface. Vectorized over samples: o, d (S, 3) → s (S,) (NaN: missed), n (S, 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.spatial.robot import Shape, SpatialRobot


@dataclass(frozen=True)
class BodySurface:
    """The solids of one body, in the body frame, with the URDF link each came from."""

    body: int
    name: str                       # the body's URDF link name
    solids: tuple                   # ((link name, Shape in the body frame), …)
    segment: tuple                  # (start, end) in the body frame: the body's axis

    @property
    def has_geometry(self) -> bool:
        return len(self.solids) > 0


def body_surfaces(robot: SpatialRobot, tree) -> list[BodySurface]:
    """Every body's solids (link frames composed into the body frame) and its segment: from the
    body origin to the farthest child joint or fixed child frame (else to twice the centre of
    mass)."""
    import pinocchio as pin

    model = robot.model
    out = []
    for b in range(tree.n_bodies):
        j = b + 1
        solids = []
        ends = []
        for fr in model.frames:
            if fr.parentJoint != j or fr.type != pin.FrameType.BODY:
                continue
            R, p = np.array(fr.placement.rotation), np.array(fr.placement.translation)
            if np.linalg.norm(p) > 0:
                ends.append(p)
            for shape in robot.shapes.get(fr.name, []):
                solids.append((fr.name, Shape(shape.kind, shape.size, R @ shape.rotation,
                                              R @ shape.origin + p, shape.mesh_path)))
        for c in range(1, tree.n_bodies):
            if tree.parent[c] == b:
                ends.append(tree.pp[c])
        end = max(ends, key=np.linalg.norm) if ends else 2 * tree.com[b]
        out.append(BodySurface(b, tree.body_names[b], tuple(solids), (np.zeros(3), np.asarray(end, float))))
    return out


# ----------------------------------------------------------------------------- line ∩ solid
def _to_local(shape: Shape, o, d):
    return (o - shape.origin) @ shape.rotation, d @ shape.rotation


def _sphere(o, d, r, c=np.zeros(3)):
    oc = o - c
    b = np.einsum("si,si->s", oc, d)
    disc = b * b - (np.einsum("si,si->s", oc, oc) - r * r)
    with np.errstate(invalid="ignore"):
        s = -b - np.sqrt(disc)
    s = np.where(disc >= 0, s, np.nan)
    n = (oc + s[:, None] * d) / r
    return s, n


def _box(o, d, size):
    h = np.asarray(size) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-h - o) / d
        t2 = (h - o) / d
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    lo = np.where(np.isnan(lo), -np.inf, lo)       # parallel to a slab and inside it
    hi = np.where(np.isnan(hi), np.inf, hi)
    par = (d == 0) & (np.abs(o) > h)
    s_in, s_out = lo.max(axis=1), hi.min(axis=1)
    hit = (s_in <= s_out) & ~par.any(axis=1)
    axis = lo.argmax(axis=1)
    n = np.zeros_like(o)
    idx = np.arange(len(o))
    n[idx, axis] = -np.sign(d[idx, axis])
    return np.where(hit, s_in, np.nan), n


def _cylinder(o, d, r, L):
    """Entry into {x² + y² ≤ r², |z| ≤ L/2}: the later of the infinite cylinder's and the slab's
    entries, if it comes before the earlier exit."""
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
    c = o[:, 0] ** 2 + o[:, 1] ** 2 - r * r
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(disc)
        c1, c2 = (-b - root) / a, (-b + root) / a
        t1, t2 = (-L / 2 - o[:, 2]) / d[:, 2], (L / 2 - o[:, 2]) / d[:, 2]
    along = a <= 1e-300                                   # parallel to the axis
    c1 = np.where(along, np.where(c <= 0, -np.inf, np.nan), np.where(disc >= 0, c1, np.nan))
    c2 = np.where(along, np.where(c <= 0, np.inf, np.nan), np.where(disc >= 0, c2, np.nan))
    flat = d[:, 2] == 0
    z1 = np.where(flat, np.where(np.abs(o[:, 2]) <= L / 2, -np.inf, np.nan), np.minimum(t1, t2))
    z2 = np.where(flat, np.where(np.abs(o[:, 2]) <= L / 2, np.inf, np.nan), np.maximum(t1, t2))
    s_in = np.maximum(c1, z1)
    s_out = np.minimum(c2, z2)
    hit = np.isfinite(s_in) & (s_in <= s_out)
    s = np.where(hit, s_in, np.nan)
    p = o + np.where(hit, s, 0.0)[:, None] * d
    cap = hit & (z1 >= c1)
    n = np.zeros_like(o)
    n[:, :2] = p[:, :2] / r
    n[cap] = 0.0
    n[cap, 2] = -np.sign(d[cap, 2])
    return s, n


def _capsule(o, d, r, L):
    s_c, n_c = _cylinder(o, d, r, L)
    lateral = np.isfinite(s_c) & (np.abs(n_c[:, 2]) < 0.5)
    s_c = np.where(lateral, s_c, np.nan)
    best_s, best_n = s_c, n_c
    for z in (-L / 2, L / 2):
        s, n = _sphere(o, d, r, np.array([0.0, 0.0, z]))
        p = o + s[:, None] * d
        ok = np.isfinite(s) & ((p[:, 2] - z) * np.sign(z) >= 0)
        take = ok & ~(best_s <= s)
        best_s = np.where(take, s, best_s)
        best_n = np.where(take[:, None], n, best_n)
    return best_s, best_n


_MESHES: dict = {}


def _mesh(shape: Shape):
    if shape.mesh_path not in _MESHES:
        import trimesh

        from userio.errors import InputError

        try:
            m = trimesh.load(shape.mesh_path, force="mesh")
        except Exception as exc:  # noqa: BLE001 — trimesh raises many types for a bad file
            raise InputError(f"{shape.mesh_path}: not a readable mesh: {exc}") from None
        _MESHES[shape.mesh_path] = m
    m = _MESHES[shape.mesh_path].copy()
    m.apply_scale(np.asarray(shape.size))
    return m


MAX_CROSSINGS = 8


def _mesh_entries(shape: Shape, o, d):
    """Every inward crossing of the line with a mesh (a concave part can have several):
    Möller–Trumbore on every (line, triangle) pair (lines in blocks of ≤ 2·10⁶ pairs); s (S, K)
    sorted, NaN-padded, K ≤ ``MAX_CROSSINGS``; crossings within 1 µm (a shared edge) count once."""
    m = _mesh(shape)
    v0 = m.vertices[m.faces[:, 0]]
    e1 = m.vertices[m.faces[:, 1]] - v0
    e2 = m.vertices[m.faces[:, 2]] - v0
    nrm = np.asarray(m.face_normals)
    S = len(o)
    K = MAX_CROSSINGS
    s_out = np.full((S, K), np.nan)
    n_out = np.zeros((S, K, 3))
    step = max(1, int(2e6 // max(len(v0), 1)))
    for a in range(0, S, step):
        oo, dd = o[a:a + step, None, :], d[a:a + step, None, :]
        pv = np.cross(dd, e2[None])
        det = np.einsum("sfi,fi->sf", pv, e1)
        with np.errstate(all="ignore"):                # parallel triangles: det = 0 → inf, NaN
            inv = 1.0 / det
            tv = oo - v0[None]
            uu = np.einsum("sfi,sfi->sf", tv, pv) * inv
            qv = np.cross(tv, e1[None])
            vv = np.einsum("sfi,sfi->sf", np.broadcast_to(dd, qv.shape), qv) * inv
            ss = np.einsum("sfi,fi->sf", qv, e2) * inv
            inward = np.einsum("sfi,fi->sf", np.broadcast_to(dd, (dd.shape[0], len(v0), 3)), nrm) < 0
            ok = (np.abs(det) > 1e-15) & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & inward
        ss = np.where(ok, ss, np.inf)
        order = np.argsort(ss, axis=1)[:, :4 * K]
        for i in range(ss.shape[0]):
            row = a + i
            k = 0
            last = -np.inf
            for f in order[i]:
                sv = ss[i, f]
                if not np.isfinite(sv) or k == K:
                    break
                if sv - last > 1e-6:
                    s_out[row, k], n_out[row, k] = sv, nrm[f]
                    k += 1
                    last = sv
    return s_out, n_out


def _inside(shape: Shape, p: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """p (S, 3, body frame) strictly inside a primitive solid (meshes: never)."""
    x = (p - shape.origin) @ shape.rotation
    if shape.kind == "sphere":
        return np.linalg.norm(x, axis=1) < shape.size[0] - tol
    if shape.kind == "box":
        return np.all(np.abs(x) < np.asarray(shape.size) / 2 - tol, axis=1)
    if shape.kind == "cylinder":
        r, L = shape.size
        return (np.hypot(x[:, 0], x[:, 1]) < r - tol) & (np.abs(x[:, 2]) < L / 2 - tol)
    if shape.kind == "capsule":
        r, L = shape.size
        z = np.clip(x[:, 2], -L / 2, L / 2)
        return np.linalg.norm(x - np.c_[np.zeros((len(x), 2)), z], axis=1) < r - tol
    return np.zeros(len(p), bool)


def entry(shape: Shape, o: np.ndarray, d: np.ndarray):
    """(s, n) of the line o + s d (body frame, (S, 3)) entering ``shape``: s (S,) NaN where it
    misses, n the outward normal in the body frame."""
    ol, dl = _to_local(shape, o, d)
    if shape.kind == "sphere":
        s, n = _sphere(ol, dl, shape.size[0])
    elif shape.kind == "box":
        s, n = _box(ol, dl, shape.size)
    elif shape.kind == "cylinder":
        s, n = _cylinder(ol, dl, *shape.size)
    elif shape.kind == "capsule":
        s, n = _capsule(ol, dl, *shape.size)
    else:
        s, n = _mesh_entries(shape, ol, dl)
        return s[:, 0], n[:, 0] @ shape.rotation.T
    return s, n @ shape.rotation.T


def entries(shape: Shape, o: np.ndarray, d: np.ndarray):
    """Every inward crossing: s (S, K), n (S, K, 3) (a convex primitive has one: K = 1)."""
    if shape.kind != "mesh":
        s, n = entry(shape, o, d)
        return s[:, None], n[:, None]
    ol, dl = _to_local(shape, o, d)
    s, n = _mesh_entries(shape, ol, dl)
    return s, n @ shape.rotation.T


def body_entry(surface: BodySurface, o: np.ndarray, d: np.ndarray):
    """The first entry of the line into any of the body's solids: (s, point, normal, link index
    into ``surface.solids``), NaN / −1 where it misses them all."""
    S = len(o)
    best = np.full(S, np.nan)
    normal = np.zeros((S, 3))
    which = np.full(S, -1)
    for i, (_, shape) in enumerate(surface.solids):
        s, n = entry(shape, o, d)
        take = np.isfinite(s) & ~(best <= s)
        best = np.where(take, s, best)
        normal = np.where(take[:, None], n, normal)
        which = np.where(take, i, which)
    return best, o + best[:, None] * d, normal, which


def body_entries(surface: BodySurface, o: np.ndarray, d: np.ndarray):
    """Every inward crossing of the line with the body's surface (the union of its solids: a
    crossing inside another of its primitive solids is not on the surface), sorted along the
    line: s (S, K) NaN-padded, outward normals (S, K, 3), solid index (S, K) (−1 padding)."""
    cols_s, cols_n, cols_i = [], [], []
    for i, (_, shape) in enumerate(surface.solids):
        s, n = entries(shape, o, d)
        p = o[:, None, :] + np.nan_to_num(s)[..., None] * d[:, None, :]
        for j, (_, other) in enumerate(surface.solids):
            if j != i:
                hidden = np.stack([_inside(other, p[:, k]) for k in range(s.shape[1])], axis=1)
                s = np.where(hidden, np.nan, s)
        cols_s.append(s)
        cols_n.append(n)
        cols_i.append(np.full(s.shape, i))
    s = np.concatenate(cols_s, axis=1)
    n = np.concatenate(cols_n, axis=1)
    idx = np.concatenate(cols_i, axis=1)
    order = np.argsort(np.where(np.isfinite(s), s, np.inf), axis=1, kind="stable")
    rows = np.arange(len(s))[:, None]
    s, n, idx = s[rows, order], n[rows, order], idx[rows, order]
    return s, n, np.where(np.isfinite(s), idx, -1)


def segment_point(surface: BodySurface, o: np.ndarray, d: np.ndarray):
    """The point of the body's segment nearest the line (body frame) and its distance."""
    a, b = surface.segment
    u = b - a
    w0 = a - o
    uu = u @ u
    ud = d @ u
    wd = np.einsum("si,si->s", w0, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = uu - ud * ud                            # |d| = 1
        alpha = np.where(den > 1e-12 * uu, (ud * wd - w0 @ u) / den, 0.5)
    alpha = np.clip(alpha, 0.0, 1.0)
    p = a + alpha[:, None] * u
    off = (p - o) - np.einsum("si,si->s", p - o, d)[:, None] * d
    return p, np.linalg.norm(off, axis=1), alpha


def surface_point(surface: BodySurface, link: str | None, along: float, around_rad: float):
    """A point on the lateral surface of a link's first cylinder/capsule (``along`` ∈ [0, 1]
    from the solid's −z end to +z, ``around_rad`` about its axis from its local +x), or on a
    sphere/box (along: polar fraction, around: azimuth) — body frame, with its outward normal."""
    from userio.errors import InputError

    solids = [(n, s) for n, s in surface.solids if link in (None, n)]
    if not solids:
        raise InputError(f"poke: link '{link or surface.name}' has no collision geometry to poke")
    _, shape = solids[0]
    c, s = np.cos(around_rad), np.sin(around_rad)
    if shape.kind in ("cylinder", "capsule"):
        r, L = shape.size
        local, n = np.array([r * c, r * s, (along - 0.5) * L]), np.array([c, s, 0.0])
    elif shape.kind == "sphere":
        th = np.pi * along
        n = np.array([np.sin(th) * c, np.sin(th) * s, -np.cos(th)])
        local = shape.size[0] * n
    elif shape.kind == "box":
        h = np.asarray(shape.size) / 2
        local, n = np.array([h[0] * c, h[1] * s, (along - 0.5) * 2 * h[2]]), np.zeros(3)
        k = int(np.argmax(np.abs(local / h)))
        local[k] = np.sign(local[k]) * h[k]
        n[k] = np.sign(local[k])
    else:
        raise InputError(f"poke: link '{link}': give the point (point_m) on a mesh explicitly")
    return shape.rotation @ local + shape.origin, shape.rotation @ n


def body_sizes(robot, tree) -> np.ndarray:
    """ℓ per body (m): the length of its segment (estimator.spatial.geometry: body origin to the
    farthest child joint or fixed child frame, else twice the centre of mass), at least
    √(tr I_c / m) (√2 × the RMS distance of its mass from the centre of mass: a ball's radius)."""
    seg = np.array([np.linalg.norm(s.segment[1] - s.segment[0]) for s in body_surfaces(robot, tree)])
    gyr = np.sqrt(np.trace(tree.Ic, axis1=1, axis2=2) / np.maximum(tree.mass, 1e-300))
    return np.maximum(seg, gyr)
