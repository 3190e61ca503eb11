"""Export and pictures of an analysis: ParaView .vtu file and an off-screen PNG of the flexure.

``Fields`` (flexure.analysis) → ``to_grid`` → pyvista UnstructuredGrid (VTK_TETRA / VTK_QUADRATIC_TETRA,
the mesh's own node ordering, coordinates in metres) with point data ``displacement_m``,
``von_mises_Pa``, ``max_shear_strain`` and ``boundary_condition`` (0 free, 1 fixed, 2 loaded).
Files are written atomically (temporary file in the target directory, then ``os.replace``), so a
failed write never leaves a half-written file or clobbers an existing one.

pyvista is imported inside the functions, never at module import time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from userio.errors import InputError
from userio.files import atomic_write

#: boundary_condition point-data codes.
BC_FREE, BC_FIXED, BC_LOADED = 0, 1, 2
#: render_png field names → (point-data array, scale to display units, colour-bar title).
FIELDS = {
    "strain": ("max_shear_strain", 1e6, "max shear strain γ/2 at rated torque (µε)"),
    "von_mises": ("von_mises_Pa", 1e-6, "von Mises stress at rated torque (MPa)"),
}
#: warp so that the largest displacement is this fraction of the bounding-box diagonal.
WARP_FRACTION = 0.05
#: camera: looking down at the top face (z max, where the gauges are) from +z, −y, +x.
VIEW_VECTOR, VIEW_UP = (0.7, -1.0, 1.3), (0.0, 0.0, 1.0)
#: points per gauge-outline edge when the outline is warped with the surface.
OUTLINE_POINTS_PER_EDGE = 16


# ----------------------------------------------------------------------------- data
def _nodal(name: str, values, n: int, width: int | None = None) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    want = (n,) if width is None else (n, width)
    if a.shape != want:
        raise InputError(f"fields: {name} must have shape {want}, got {a.shape}")
    return a


def _node_set(name: str, idx, n: int) -> np.ndarray:
    a = np.asarray(idx if idx is not None else [], dtype=np.int64).ravel()
    if a.size and (a.min() < 0 or a.max() >= n):
        raise InputError(f"fields: {name} refers to node {int(a.max() if a.max() >= n else a.min())}, "
                         f"but there are {n} points")
    return a


def boundary_codes(n: int, fixed_nodes, load_nodes) -> np.ndarray:
    """(n,) int8: 0 free, 1 fixed, 2 loaded (a node in both sets counts as fixed)."""
    code = np.zeros(n, dtype=np.int8)
    code[_node_set("load_nodes", load_nodes, n)] = BC_LOADED
    code[_node_set("fixed_nodes", fixed_nodes, n)] = BC_FIXED
    return code


def to_grid(fields):
    """Fields → pyvista.UnstructuredGrid of TETRA (P1) or QUADRATIC_TETRA (P2) cells with point data."""
    import pyvista as pv

    mesh = fields.mesh
    pts = np.asarray(mesh.points, dtype=np.float64)
    tets = np.asarray(mesh.tets, dtype=np.int64)
    n, (m, k) = len(pts), tets.shape
    if k not in (4, 10):
        raise InputError(f"fields: mesh.tets must have 4 or 10 nodes per element, got {k}")
    ctype = pv.CellType.TETRA if k == 4 else pv.CellType.QUADRATIC_TETRA
    cells = np.hstack([np.full((m, 1), k, dtype=np.int64), tets]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(m, ctype, dtype=np.uint8), pts.copy())
    grid.point_data["displacement_m"] = _nodal("u_rated_m", fields.u_rated_m, n, 3)
    grid.point_data["von_mises_Pa"] = _nodal("von_mises_Pa", fields.von_mises_Pa, n)
    grid.point_data["max_shear_strain"] = _nodal("strain_eq", fields.strain_eq, n)
    grid.point_data["boundary_condition"] = boundary_codes(n, fields.fixed_nodes, fields.load_nodes)
    return grid


def _gauge_corners(gauges) -> tuple[np.ndarray, np.ndarray]:
    """(g,4,3) grid corners (counter-clockwise seen from outside) and (g,3) unit normals."""
    corners, normals = [], []
    for g in gauges:
        c, a, b, nrm = g.frame()
        hl, hw = 0.5 * g.length_m, 0.5 * g.width_m
        corners.append([c - hl * a - hw * b, c + hl * a - hw * b, c + hl * a + hw * b, c - hl * a + hw * b])
        normals.append(nrm)
    return np.reshape(corners, (-1, 4, 3)), np.reshape(normals, (-1, 3))


def _lift(gauges) -> np.ndarray:
    """(g,) outward lift of each outline: 1e-3·min(L, W)."""
    return np.array([1e-3 * min(g.length_m, g.width_m) for g in gauges], dtype=np.float64)


def gauge_outlines(gauges, per_edge: int = 1):
    """Gauge grids as closed rectangle polylines (corners c ± a·L/2 ± b·W/2), lifted along the
    normal by 1e-3·min(L, W); cell data ``arm``.

    Points: per gauge, 4·per_edge points going round the rectangle from corner c − a·L/2 − b·W/2
    (corners at multiples of ``per_edge``); ``per_edge`` > 1 adds points along the edges so the
    outline can follow a warped surface.
    """
    import pyvista as pv

    gauges = list(gauges)
    if not gauges:
        return pv.PolyData()
    pts = _outline_points(gauges, per_edge)
    g, k = pts.shape[:2]
    base = k * np.arange(g, dtype=np.int64)[:, None]
    ring = np.append(np.arange(k), 0)
    lines = np.hstack([np.full((g, 1), k + 1, dtype=np.int64), base + ring])
    poly = pv.PolyData(pts.reshape(-1, 3), lines=lines.ravel())
    poly.cell_data["arm"] = np.array([int(gg.arm) for gg in gauges], dtype=np.int64)
    return poly


def _outline_points(gauges, per_edge: int = 1, lift: bool = True) -> np.ndarray:
    """(g, 4·per_edge, 3) points round each gauge rectangle, lifted (or not) along its normal."""
    per_edge = max(int(per_edge), 1)
    corners, normals = _gauge_corners(gauges)
    t = (np.arange(per_edge) / per_edge)[None, None, :, None]
    nxt = np.roll(corners, -1, axis=1)
    pts = (corners[:, :, None] + t * (nxt - corners)[:, :, None]).reshape(len(gauges), -1, 3)
    if lift:
        pts = pts + (_lift(gauges)[:, None] * normals)[:, None, :]
    return pts


# ----------------------------------------------------------------------------- files
def _check_target(path, suffix: str) -> Path:
    """Path with the right suffix in an existing directory, else InputError."""
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise InputError(f"{path}: expected a {suffix} file name, got suffix {path.suffix or '(none)'!r}")
    parent = path.parent
    if not parent.is_dir():
        raise InputError(f"{path}: directory {parent} does not exist")
    if path.is_dir():
        raise InputError(f"{path}: is a directory")
    return path


def write_vtu(fields, path) -> Path:
    """Write ``to_grid(fields)`` as a binary VTK XML unstructured grid (.vtu, opens in ParaView)."""
    path = _check_target(path, ".vtu")
    grid = to_grid(fields)
    return atomic_write(path, lambda tmp: grid.save(tmp, binary=True))


# ----------------------------------------------------------------------------- picture
def warp_factor(points: np.ndarray, u: np.ndarray, fraction: float = WARP_FRACTION) -> float:
    """Scale making max |u| equal to ``fraction`` of the bounding-box diagonal (0 if u ≡ 0)."""
    diag = float(np.linalg.norm(np.ptp(points, axis=0)))
    umax = float(np.sqrt((np.asarray(u) ** 2).sum(axis=1).max())) if len(u) else 0.0
    return fraction * diag / umax if umax > 0 and np.isfinite(umax) else 0.0


def _displacement_at(grid, pts: np.ndarray) -> np.ndarray:
    """Interpolated displacement at points (k,3): probe the grid, nearest node where the probe misses."""
    import pyvista as pv

    probe = pv.PolyData(pts).sample(grid)
    u = np.asarray(probe.point_data["displacement_m"], dtype=np.float64).reshape(-1, 3)
    valid = np.asarray(probe.point_data["vtkValidPointMask"]).astype(bool)
    for i in np.flatnonzero(~valid):
        u[i] = grid.point_data["displacement_m"][grid.find_closest_point(pts[i])]
    return u


def _surface(grid):
    """Outer surface as linear triangles (P2 faces split at their mid-edge nodes), point data kept."""
    try:
        return grid.extract_surface(nonlinear_subdivision=1, algorithm="dataset_surface")
    except TypeError:                                  # pyvista < 0.47: no ``algorithm`` keyword
        return grid.extract_surface(nonlinear_subdivision=1)


def _font_file() -> str | None:
    """A TrueType font with γ, µ, ε, × (VTK's built-in fonts lack Greek): DejaVu Sans, or None."""
    import importlib.util

    cands = []
    spec = importlib.util.find_spec("matplotlib")
    if spec is not None and spec.submodule_search_locations:
        cands.append(Path(list(spec.submodule_search_locations)[0]) / "mpl-data/fonts/ttf/DejaVuSans.ttf")
    cands.append(Path("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"))
    return next((str(p) for p in cands if p.is_file()), None)


def _ascii(text: str) -> str:
    """Fallback labels when no Unicode font is available."""
    for a, b in (("γ", "gamma"), ("µε", "microstrain"), ("×", "x"), ("µ", "u"), ("ε", "eps")):
        text = text.replace(a, b)
    return text


def _unavailable(exc: BaseException) -> InputError:
    msg = " ".join(str(exc).split()) or type(exc).__name__
    return InputError(f"--png: off-screen rendering is unavailable ({msg})")


def render_png(fields, path, field: str = "strain", title: str | None = None, warp: bool = True,
               window_size=(1200, 900)) -> Path:
    """Off-screen picture of the (optionally warped) surface coloured by ``field`` with gauges outlined.

    field "strain": max shear strain γ/2 in µε; "von_mises": von Mises stress in MPa. With ``warp``
    the geometry is displaced so the largest displacement is 5 % of the bounding-box diagonal; the
    factor is printed under the title. Fixed nodes are grey dots, loaded nodes blue dots.
    """
    if field not in FIELDS:
        raise InputError(f"render: unknown field {field!r}; allowed: {', '.join(sorted(FIELDS))}")
    path = _check_target(path, ".png")
    from userio.offscreen import prefer_headless

    prefer_headless()                      # no reachable X server: EGL (no X warning on stderr)
    try:
        import pyvista as pv
    except (ImportError, OSError) as exc:
        raise _unavailable(exc) from exc

    array, scale, bar_title = FIELDS[field]
    grid = to_grid(fields)
    pts0 = np.asarray(grid.points)
    u = np.asarray(grid.point_data["displacement_m"])
    factor = warp_factor(pts0, u) if warp else 0.0

    surf = _surface(grid)
    surf.point_data["shown"] = np.asarray(surf.point_data[array]) * scale
    if factor:
        surf.points = np.asarray(surf.points) + factor * np.asarray(surf.point_data["displacement_m"])

    gauges = list(fields.gauges or [])
    outline = label_pts = None
    if gauges:
        outline = gauge_outlines(gauges, per_edge=OUTLINE_POINTS_PER_EDGE if factor else 1)
        normals = _gauge_corners(gauges)[1]
        if factor:   # move the outline with the surface: displacement probed a hair inside the solid
            inset = 1e-4 * np.array([min(g.length_m, g.width_m) for g in gauges])[:, None] * normals
            probe = (_outline_points(gauges, OUTLINE_POINTS_PER_EDGE, lift=False)
                     - inset[:, None, :]).reshape(-1, 3)
            du = _displacement_at(grid, probe)
            outline.points = np.asarray(outline.points) + factor * du
        # label just right (on screen) of each outline, so it does not hide the grid
        ring = np.asarray(outline.points).reshape(len(gauges), -1, 3)
        right = np.cross(-np.asarray(VIEW_VECTOR, float), VIEW_UP)
        right /= np.linalg.norm(right)
        far = ring[np.arange(len(gauges)), np.argmax(ring @ right, axis=1)]
        label_pts = far + 0.5 * np.array([max(g.length_m, g.width_m) for g in gauges])[:, None] * right
    fixed = np.asarray(fields.fixed_nodes if fields.fixed_nodes is not None else [], dtype=np.int64)
    loaded = np.asarray(fields.load_nodes if fields.load_nodes is not None else [], dtype=np.int64)
    moved = pts0 + factor * u

    font = _font_file()
    text = (lambda t: t) if font else _ascii
    head = title if title is not None else f"flexure: {bar_title.split(' at ')[0]}"
    sub = [f"displacement ×{factor:.4g}" if factor else "undeformed geometry"]
    if len(fixed):
        sub.append("grey: fixed nodes")
    if len(loaded):
        sub.append("blue: loaded nodes")
    if gauges:
        sub.append("black: gauges (bridge arm)")

    def draw(tmp):
        try:
            plotter = pv.Plotter(off_screen=True, window_size=[int(v) for v in window_size])
        except Exception as exc:                      # no OpenGL / no display backend
            raise _unavailable(exc) from exc
        try:
            plotter.set_background("white")
            plotter.add_mesh(surf, scalars="shown", cmap="turbo", show_scalar_bar=False)
            bar = plotter.add_scalar_bar(title=text(bar_title), color="black", vertical=False,
                                         position_x=0.2, position_y=0.03, width=0.6, height=0.08,
                                         title_font_size=18, label_font_size=16, fmt="%.4g")
            if font:                                  # title has γ, µ, ε (labels are plain numbers)
                bar.GetTitleTextProperty().SetFontFamily(4)      # VTK_FONT_FILE
                bar.GetTitleTextProperty().SetFontFile(font)
            if len(fixed):
                plotter.add_points(moved[fixed], color="grey", point_size=5, render_points_as_spheres=True)
            if len(loaded):
                plotter.add_points(moved[loaded], color="blue", point_size=5, render_points_as_spheres=True)
            if outline is not None:
                # tubes: plain wide lines are 1 px on many off-screen GL contexts
                plotter.add_mesh(outline, color="black", line_width=3, render_lines_as_tubes=True)
                plotter.add_point_labels(label_pts, [str(g.arm) for g in gauges], font_size=16,
                                         text_color="black", shape_color="white", shape_opacity=0.7,
                                         show_points=False, always_visible=True)
            plotter.add_text(text(head), position="upper_left", font_size=14, color="black", font_file=font)
            plotter.add_text(text("\n".join(sub)), position="upper_right", font_size=10, color="black",
                             font_file=font)
            plotter.view_vector(VIEW_VECTOR, viewup=VIEW_UP)
            plotter.reset_camera()
            try:
                plotter.screenshot(tmp)
            except Exception as exc:
                raise _unavailable(exc) from exc
        finally:
            plotter.close()

    return atomic_write(path, draw)
