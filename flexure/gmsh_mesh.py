"""Graded isotropic tetrahedral meshes with gmsh's size fields, for every kind of input.

The size at a point is the project's ``meshing.SizeField`` of the distance d to the nearest
gauge centre (a Distance/Threshold field), given to gmsh as its size callback:

    h(d) = clip(h_gauge + g (d − r_gauge), h_gauge, h_far),   g = 0.35 (grading).
 The *volume* is meshed with this field (not
just the surface, as with tetgen), so a gauge is covered by several isotropic elements whatever
the STL's triangles: an STL is re-meshed through gmsh's ``classifySurfaces``/``createGeometry``
(its triangles only define the shape), a parametric profile is extruded in OpenCASCADE and a STEP
solid is meshed directly on its exact geometry. gmsh's Delaunay 3-D + Netgen optimisation keeps the minimum dihedral
angle well above 10°. Everything in gmsh is in millimetres (its tolerances are absolute).
"""

from __future__ import annotations

import numpy as np

from flexure.errors import InputError

MM = 1e3                        # metres → gmsh units (mm)


def _size_field(gmsh, field) -> None:
    """Mesh size from ``field`` (meshing.SizeField, metres: h = clip(h_gauge + g(d − r_gauge),
    h_gauge, h_far)) through gmsh's size callback, in mm."""
    c = np.asarray(field.centres, float).reshape(-1, 3) * MM
    h0, h1, r0, g = field.h_gauge * MM, field.h_far * MM, field.r_gauge * MM, field.grading

    def size(dim, tag, x, y, z, lc):
        if not len(c):
            return h1
        d = float(np.sqrt(((c - (x, y, z)) ** 2).sum(1)).min())
        return min(max(h0 + g * (d - r0), h0), h1)

    gmsh.model.mesh.setSizeCallback(size)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", h1)


def _volume_tets(gmsh, where: str):
    """Generate the 3-D mesh (Delaunay, Netgen-optimised) → (points m, corner tets)."""
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.option.setNumber("Mesh.OptimizeNetgen", 1)
    try:
        gmsh.model.mesh.generate(3)
    except Exception as exc:
        raise InputError(f"{where}: gmsh could not mesh the volume ({str(exc).splitlines()[0]})") from None
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, enodes = gmsh.model.mesh.getElementsByType(4)
    if len(enodes) == 0:
        raise InputError(f"{where}: gmsh produced no tetrahedra (is the surface closed?)")
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    tets = index[np.asarray(enodes, np.int64)].reshape(-1, 4)
    used = np.unique(tets)
    remap = np.full(len(tags), -1)
    remap[used] = np.arange(len(used))
    points = np.asarray(coords, float).reshape(-1, 3)[used] / MM
    tets = remap[tets]
    x = points[tets]
    vol = np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return points, tets


def _session(build, field, where: str, order: int):
    """Run ``build(gmsh)`` (creates the volume), mesh it with ``field``; → flexure.mesh.Mesh."""
    import gmsh

    from flexure.cad import _quiet_stdout
    from flexure.mesh import Mesh, to_quadratic

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        with _quiet_stdout():
            build(gmsh)
            _size_field(gmsh, field)
            points, tets = _volume_tets(gmsh, where)
    finally:
        gmsh.finalize()
    mesh = Mesh(points, tets)
    return to_quadratic(mesh) if order == 2 else mesh


def mesh_extrusion(poly, height: float, field, order: int = 1, where: str = "mesh"):
    """Graded isotropic mesh of the shapely polygon ``poly`` (m) extruded to ``height`` (m)."""

    def build(gmsh):
        occ = gmsh.model.occ
        loops = []
        for ring in [poly.exterior] + list(poly.interiors):
            xy = np.asarray(ring.coords)[:-1] * MM
            p = [occ.addPoint(x, y, 0.0) for x, y in xy]
            lines = [occ.addLine(p[i], p[(i + 1) % len(p)]) for i in range(len(p))]
            loops.append(occ.addCurveLoop(lines))
        s = occ.addPlaneSurface(loops)
        occ.extrude([(2, s)], 0, 0, height * MM)
        occ.synchronize()

    return _session(build, field, where, order)


def mesh_surface(surface, field, order: int = 1, where: str = "mesh", angle_deg: float = 40.0):
    """Re-mesh a closed triangulated surface (STL, m) and its volume with the size field: the
    triangles are classified into patches (dihedral angle > ``angle_deg`` = sharp edge), each patch
    re-parametrised and re-triangulated at the field's size, then the volume is meshed."""

    def build(gmsh):
        gmsh.model.add("stl")
        tag = gmsh.model.addDiscreteEntity(2)
        n = len(surface.points)
        gmsh.model.mesh.addNodes(2, tag, np.arange(1, n + 1), (surface.points * MM).ravel())
        gmsh.model.mesh.addElementsByType(tag, 2, [], (np.asarray(surface.faces) + 1).ravel())
        gmsh.model.mesh.classifySurfaces(np.deg2rad(angle_deg), True, True, np.pi)
        gmsh.model.mesh.createGeometry()
        surfs = [t for _, t in gmsh.model.getEntities(2)]
        loop = gmsh.model.geo.addSurfaceLoop(surfs)
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()

    return _session(build, field, where, order)


def mesh_step(path, unit_m: float, field, order: int = 1, where: str = "geometry.file"):
    """Graded mesh of the one solid of a STEP file (``unit_m`` metres per file unit), meshed on
    the exact OpenCASCADE geometry (no intermediate triangulation)."""
    scale = unit_m * MM

    def build(gmsh):
        gmsh.model.occ.importShapes(str(path))
        gmsh.model.occ.synchronize()
        if abs(scale - 1.0) > 1e-12:
            gmsh.model.occ.dilate(gmsh.model.getEntities(3), 0, 0, 0, scale, scale, scale)
            gmsh.model.occ.synchronize()

    return _session(build, field, where, order)
