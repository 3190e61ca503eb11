"""flexure.render: VTU export, gauge outlines, off-screen PNG and atomic writes, on a hand-built box."""

import os
import subprocess
import sys

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")

from flexure import render  # noqa: E402
from flexure.analysis import Fields  # noqa: E402
from userio.errors import InputError  # noqa: E402
from userio.files import atomic_write  # noqa: E402
from flexure.gauges import Gauge  # noqa: E402
from flexure.mesh import Mesh, box_mesh, to_quadratic  # noqa: E402

SIZE = (0.04, 0.02, 0.005)            # m
GAMMA = 1e-3                           # shear u_x = γ z
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def make_fields(order=1, gauges=None):
    mesh = box_mesh(4, 2, 2, size=SIZE)
    if order == 2:
        mesh = to_quadratic(mesh)
    p = mesh.points
    u = np.column_stack([GAMMA * p[:, 2], np.zeros(len(p)), np.zeros(len(p))])
    ramp = 1.0 + p[:, 0] / SIZE[0]
    fixed = np.flatnonzero(np.isclose(p[:, 0], 0.0))
    load = np.flatnonzero(np.isclose(p[:, 0], SIZE[0]))
    if gauges is None:
        gauges = [Gauge((0.01, 0.01, SIZE[2]), (1, 1, 0), (0, 0, 1), 0.004, 0.003, 1, "g1"),
                  Gauge((0.03, 0.01, SIZE[2]), (1, -1, 0), (0, 0, 1), 0.004, 0.003, 2, "g2")]
    return Fields(mesh, u, 80e6 * ramp, 0.5 * GAMMA * ramp, gauges, fixed, load)


@pytest.fixture(params=[1, 2], ids=["P1", "P2"])
def fields(request):
    return make_fields(request.param)


def _expected_type(fields):
    return pv.CellType.TETRA if fields.mesh.order == 1 else pv.CellType.QUADRATIC_TETRA


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


# ----------------------------------------------------------------------------- grid
def test_grid_cells_point_data_and_volume(fields):
    grid = render.to_grid(fields)
    mesh = fields.mesh
    assert grid.n_points == mesh.n_nodes and grid.n_cells == mesh.n_elements
    assert np.all(grid.celltypes == _expected_type(fields))
    np.testing.assert_array_equal(grid.cells_dict[_expected_type(fields)], mesh.tets)
    np.testing.assert_allclose(grid.points, mesh.points)
    np.testing.assert_allclose(grid["displacement_m"], fields.u_rated_m)
    np.testing.assert_allclose(grid["max_shear_strain"], fields.strain_eq)
    np.testing.assert_allclose(grid["von_mises_Pa"], fields.von_mises_Pa)
    # node ordering: VTK's own volumes are positive and add up to the box
    vol = grid.compute_cell_sizes()["Volume"]
    assert vol.min() > 0
    assert vol.sum() == pytest.approx(np.prod(SIZE), rel=1e-9)


def test_volume_check_detects_a_wrong_node_ordering(fields):
    """The volume test above has teeth: a permuted ordering gives wrong volumes."""
    perm = [0, 2, 1, 3] if fields.mesh.order == 1 else [0, 1, 2, 3, 4, 6, 5, 7, 8, 9]
    fields.mesh = Mesh(fields.mesh.points, fields.mesh.tets[:, perm])
    vol = render.to_grid(fields).compute_cell_sizes()["Volume"]
    assert abs(vol.sum() - np.prod(SIZE)) > 1e-3 * np.prod(SIZE)


def test_boundary_codes_fixed_wins_over_loaded():
    code = render.boundary_codes(5, fixed_nodes=[0, 2], load_nodes=[2, 4])
    assert code.dtype == np.int8
    assert code.tolist() == [1, 0, 1, 0, 2]
    with pytest.raises(InputError, match="fixed_nodes"):
        render.boundary_codes(5, fixed_nodes=[5], load_nodes=[])


def test_grid_rejects_wrong_field_shape():
    f = make_fields()
    f.strain_eq = f.strain_eq[:-1]
    with pytest.raises(InputError, match="strain_eq"):
        render.to_grid(f)


# ----------------------------------------------------------------------------- vtu
def test_vtu_round_trip(fields, tmp_path):
    path = tmp_path / "box.vtu"
    assert render.write_vtu(fields, path) == path
    back = pv.read(path)
    assert back.n_points == fields.mesh.n_nodes and back.n_cells == fields.mesh.n_elements
    assert set(np.unique(back.celltypes).tolist()) == {int(_expected_type(fields))}
    np.testing.assert_array_equal(back.cells_dict[_expected_type(fields)], fields.mesh.tets)
    np.testing.assert_allclose(back.points, fields.mesh.points)
    np.testing.assert_allclose(back["displacement_m"], fields.u_rated_m)
    np.testing.assert_allclose(back["max_shear_strain"], fields.strain_eq)
    np.testing.assert_allclose(back["von_mises_Pa"], fields.von_mises_Pa)
    bc = np.asarray(back["boundary_condition"])
    assert np.issubdtype(bc.dtype, np.integer)
    assert np.all(bc[fields.fixed_nodes] == 1) and np.all(bc[fields.load_nodes] == 2)
    free = np.setdiff1d(np.arange(fields.mesh.n_nodes), np.r_[fields.fixed_nodes, fields.load_nodes])
    assert len(free) > 0 and np.all(bc[free] == 0)
    assert back.compute_cell_sizes()["Volume"].sum() == pytest.approx(np.prod(SIZE), rel=1e-9)
    # atomic write: no temp file left, ordinary permissions
    assert os.listdir(tmp_path) == ["box.vtu"]
    assert (path.stat().st_mode & 0o777) == (0o666 & ~_umask())


def test_vtu_replaces_existing_file(tmp_path):
    path = tmp_path / "box.vtu"
    path.write_bytes(b"old")
    render.write_vtu(make_fields(), str(path))
    assert pv.read(path).n_cells == make_fields().mesh.n_elements
    assert os.listdir(tmp_path) == ["box.vtu"]


@pytest.mark.parametrize("name", ["box.vtk", "box", "box.vtu.png"])
def test_vtu_wrong_suffix(tmp_path, name):
    path = tmp_path / name
    with pytest.raises(InputError, match=str(path).replace(".", r"\.")):
        render.write_vtu(make_fields(), path)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("write, name", [("write_vtu", "box.vtu"), ("render_png", "out.png")])
def test_missing_directory(tmp_path, write, name):
    path = tmp_path / "nope" / name
    with pytest.raises(InputError) as err:
        getattr(render, write)(make_fields(), path)
    assert str(err.value) == f"{path}: directory {path.parent} does not exist"
    assert os.listdir(tmp_path) == []


# ----------------------------------------------------------------------------- gauges
def test_gauge_outline_corners():
    L, W = 0.004, 0.003
    top = Gauge((0.01, 0.01, SIZE[2]), (1, 1, 0), (0, 0, 1), L, W, 3, "top")
    side = Gauge((0.02, 0.0, 0.0025), (1, 0, 0.2), (0, -1, 0), 0.006, 0.002, 4, "side")  # axis not ⟂ n
    poly = render.gauge_outlines([top, side])
    assert poly.n_points == 8 and poly.n_cells == 2
    assert poly.cell_data["arm"].tolist() == [3, 4]
    lines = poly.lines.reshape(2, 6)
    assert lines[:, 0].tolist() == [5, 5]                             # 5 point ids: closed ring
    assert np.all(lines[:, 1] == lines[:, 5])
    for k, g in enumerate([top, side]):
        c, a, b, n = g.frame()
        d = poly.points[lines[k, 1:5]] - c
        hl, hw = g.length_m / 2, g.width_m / 2
        lift = 1e-3 * min(g.length_m, g.width_m)
        np.testing.assert_allclose(d @ n, lift, atol=1e-12)           # a hair outside the surface
        in_plane = d - np.outer(d @ n, n)
        np.testing.assert_allclose(np.linalg.norm(in_plane, axis=1), np.hypot(hl, hw), rtol=1e-12)
        st = np.column_stack([d @ a, d @ b])
        assert sorted(map(tuple, np.round(st / [hl, hw], 12))) == [(-1, -1), (-1, 1), (1, -1), (1, 1)]
        # consecutive corners are joined by the sides of length L, W, L, W (a rectangle, not a bow-tie)
        sides = np.linalg.norm(np.diff(poly.points[lines[k, 1:]], axis=0), axis=1)
        np.testing.assert_allclose(np.sort(sides), np.sort([2 * hl, 2 * hw] * 2), rtol=1e-12)


def test_gauge_outline_edge_points_and_empty():
    g = make_fields().gauges[0]
    dense = render.gauge_outlines([g], per_edge=4)
    plain = render.gauge_outlines([g])
    assert dense.n_points == 16
    np.testing.assert_allclose(dense.points[::4], plain.points)
    assert render.gauge_outlines([]).n_points == 0


# ----------------------------------------------------------------------------- png
def _check_png(path, size):
    import matplotlib.image as mpimg

    with open(path, "rb") as fh:
        assert fh.read(8) == PNG_SIGNATURE
    img = mpimg.imread(path)
    assert img.shape[:2] == (size[1], size[0])
    rgb = np.round(img[..., :3] * 255).astype(int)
    assert rgb.std() > 0
    n_colours = len(np.unique(rgb.reshape(-1, 3), axis=0))
    assert n_colours > 50                                              # a colour map, not a flat fill
    return rgb


@pytest.mark.parametrize("field", ["strain", "von_mises"])
def test_render_png(tmp_path, field):
    path = tmp_path / f"{field}.png"
    size = (480, 360)
    assert render.render_png(make_fields(), path, field=field, window_size=size) == path
    _check_png(path, size)
    assert os.listdir(tmp_path) == [path.name]
    assert (path.stat().st_mode & 0o777) == (0o666 & ~_umask())


def test_render_png_p2_unwarped_and_zero_displacement(tmp_path):
    f = make_fields(2)
    render.render_png(f, tmp_path / "p2.png", warp=False, window_size=(320, 240), title="P2 box")
    _check_png(tmp_path / "p2.png", (320, 240))
    f.u_rated_m = np.zeros_like(f.u_rated_m)                         # warp factor 0, no division
    render.render_png(f, tmp_path / "zero.png", window_size=(320, 240))
    _check_png(tmp_path / "zero.png", (320, 240))


def test_warp_factor():
    pts = np.array([[0, 0, 0], [3.0, 4.0, 12.0]])                      # diagonal 13
    u = np.array([[0, 0, 0], [0, 2e-6, 0]])
    assert render.warp_factor(pts, u) == pytest.approx(0.05 * 13 / 2e-6)
    assert render.warp_factor(pts, np.zeros((2, 3))) == 0.0


@pytest.mark.parametrize("name", ["out.jpg", "out", "out.vtu"])
def test_png_wrong_suffix(tmp_path, name):
    with pytest.raises(InputError, match=name.replace(".", r"\.")):
        render.render_png(make_fields(), tmp_path / name)
    assert os.listdir(tmp_path) == []


def test_png_bad_field(tmp_path):
    with pytest.raises(InputError) as err:
        render.render_png(make_fields(), tmp_path / "out.png", field="stress")
    assert "'stress'" in str(err.value)
    assert "strain" in str(err.value) and "von_mises" in str(err.value)
    assert os.listdir(tmp_path) == []


def test_png_rendering_failure_leaves_existing_file(tmp_path, monkeypatch):
    path = tmp_path / "out.png"
    path.write_bytes(b"previous picture")

    def broken(self, *args, **kwargs):
        raise RuntimeError("no OpenGL context")

    monkeypatch.setattr(pv.Plotter, "screenshot", broken)
    with pytest.raises(InputError, match=r"^--png: off-screen rendering is unavailable \(no OpenGL context\)$"):
        render.render_png(make_fields(), path, window_size=(200, 150))
    assert path.read_bytes() == b"previous picture"
    assert os.listdir(tmp_path) == ["out.png"]


def test_png_plotter_creation_failure(tmp_path, monkeypatch):
    def no_plotter(*args, **kwargs):
        raise RuntimeError("Could not create OpenGL context")

    monkeypatch.setattr(pv, "Plotter", no_plotter)
    with pytest.raises(InputError, match="off-screen rendering is unavailable .*OpenGL"):
        render.render_png(make_fields(), tmp_path / "out.png")
    assert os.listdir(tmp_path) == []


# ----------------------------------------------------------------------------- atomic helper
def test_atomic_write_failure_keeps_old_file_and_cleans_up(tmp_path):
    path = tmp_path / "out.vtu"
    path.write_bytes(b"old contents")
    seen = []

    def half_write(tmp):
        seen.append(tmp)
        assert os.path.dirname(tmp) == str(tmp_path)
        assert os.path.basename(tmp).startswith(".out.vtu") and tmp.endswith(".vtu")
        with open(tmp, "wb") as fh:
            fh.write(b"partial")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(path, half_write)
    assert path.read_bytes() == b"old contents"
    assert os.listdir(tmp_path) == ["out.vtu"]
    assert seen and not os.path.exists(seen[0])


def test_atomic_write_interrupt_and_vanished_temp(tmp_path):
    path = tmp_path / "x.png"

    def interrupted(tmp):
        os.unlink(tmp)                     # the temp file is already gone: still re-raise the original
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(path, interrupted)
    assert os.listdir(tmp_path) == []


def test_atomic_write_mode_follows_umask(tmp_path):
    old = os.umask(0o027)
    try:
        atomic_write(tmp_path / "m.png", lambda tmp: open(tmp, "wb").close())
    finally:
        os.umask(old)
    assert ((tmp_path / "m.png").stat().st_mode & 0o777) == 0o640


# ----------------------------------------------------------------------------- import cost
def test_import_does_not_load_pyvista_or_torquebench():
    code = ("import sys, flexure.render; "
            "print('pyvista' in sys.modules, any(m.split('.')[0] == 'torquebench' for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
