"""STEP solids through gmsh's OpenCASCADE kernel (optional extra: ``pip install torquebench[step]``).

The solid's boundary is triangulated by gmsh with our size field (finer at the gauges) and handed
on as a closed, outward-oriented ``Surface`` for tetgen, exactly like an STL.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from userio.errors import CallbackInterrupt, InputError

from flexure.geometry import Surface, check_watertight
from flexure.gmsh_session import LC_INTEGRATION_PRECISION, _quiet_stdout, open_session

_INTERRUPT = CallbackInterrupt()     # Ctrl-C inside gmsh's size callback → KeyboardInterrupt after it


def import_step(gmsh, path) -> None:
    """Read a STEP file into gmsh's OpenCASCADE model, in mm whatever length unit the file declares
    (OpenCASCADE converts it: a STEP file carries its unit, so none is asked of the user)."""
    gmsh.option.setString("Geometry.OCCTargetUnit", "MM")
    gmsh.model.occ.importShapes(str(path))
    gmsh.model.occ.synchronize()


def load_step(path: str | Path, size_for=None, where: str = "geometry.file",
              max_elements: float | None = None) -> Surface:
    """Surface (m) of the one solid in a STEP file (``import_step``). ``size_for(scale_m) -> SizeField`` gives the
    surface mesh size (m) from the solid's smallest bounding-box extent, never coarser than 16
    triangles per turn of a curved face: a fillet tessellated coarser folds by more than
    meshing.EDGE_ANGLE_DEG between its triangles and would read as a sharp re-entrant edge (the
    STEP part's 1 mm fillets did at h × √2 and h × 1/√2 but not at h × 1). With ``max_elements``
    the volume mesh's estimated cost (flexure.sizing.check_cost, from the solid's volume and area)
    refuses a hopeless part before its surface is meshed."""
    unit_m = 1e-3                                       # import_step reads every STEP in mm
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{where}: {path} does not exist")
    try:
        import gmsh
    except ImportError:
        raise InputError(f"{where}: {path}: STEP files need gmsh (pip install torquebench[step])") from None
    open_session(gmsh)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        with _quiet_stdout():
            try:
                import_step(gmsh, path)
            except Exception as exc:
                raise InputError(f"{where}: {path}: cannot read STEP ({str(exc).splitlines()[0]})") from None
            solids = gmsh.model.getEntities(3)
            if len(solids) != 1:
                raise InputError(f"{where}: {path}: {len(solids)} solids; the flexure must be one solid "
                                 "(fuse the bodies in your CAD tool)")
            box = np.array(gmsh.model.getBoundingBox(-1, -1))
            scale_m = float((box[3:] - box[:3]).min()) * unit_m
            if size_for is not None:
                field = size_for(scale_m)
                if max_elements is not None:           # the volume's cost, before its surface is meshed
                    from flexure.sizing import check_cost
                    tag = solids[0][1]
                    area = sum(gmsh.model.occ.getMass(2, t) for _, t in gmsh.model.getBoundary([(3, tag)], oriented=False))
                    check_cost(field, gmsh.model.occ.getMass(3, tag) * unit_m ** 3, area * unit_m ** 2,
                               max_elements, f"{where}: {path}")
                gmsh.model.mesh.setSizeCallback(_INTERRUPT.wrap(   # Ctrl-C: size 0 stops gmsh
                    lambda dim, tag, x, y, z, lc: min(lc, float(field(np.array([[x, y, z]]) * unit_m)[0]) / unit_m),
                    0.0))
                gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
                gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
                gmsh.option.setNumber("Mesh.LcIntegrationPrecision", LC_INTEGRATION_PRECISION)
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 16)     # elements per 2π of a hole
            try:
                gmsh.model.mesh.generate(2)
            finally:
                _INTERRUPT.check()
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
        index[tags.astype(np.int64)] = np.arange(len(tags))
        tri = []
        for dim, tag in gmsh.model.getEntities(2):
            types, _, nodes = gmsh.model.mesh.getElements(dim, tag)
            for t, n in zip(types, nodes):
                if t != 2:                                                # 3-node triangles
                    raise InputError(f"{where}: {path}: gmsh gave element type {t} on surface {tag}")
                tri.append(index[np.asarray(n, dtype=np.int64)].reshape(-1, 3))
    finally:
        gmsh.finalize()
    points = np.asarray(coords, float).reshape(-1, 3) * unit_m
    faces = np.vstack(tri)
    import trimesh

    tm = trimesh.Trimesh(points, faces, process=True)               # merges seam duplicates
    trimesh.repair.fix_normals(tm)
    if tm.volume < 0:
        tm.invert()
    surf = Surface(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64), source=str(path),
                   info={"cad": "step", "triangles": int(len(tm.faces))})
    check_watertight(surf, f"{where} {path}")
    return surf
