"""Bad geometry refused before meshing: exit 2, one line naming the file and the problem.

Non-watertight, self-intersecting and zero-thickness STL solids; gauges off the surface, off the
part, larger than their face, or with the wrong normal. A guard makes any meshing call fail the
test, so each refusal is shown to come before the mesher runs."""

from pathlib import Path

import numpy as np
import pytest

from flexure.design import load_design
from userio.errors import InputError
from flexure.geometry import Surface, extrude, spoke_disc_surface
from flexure.surface_check import check_gauges, check_solid, self_intersections, thin_walls
from torquebench.cli import main

SCENES = Path(__file__).resolve().parents[1] / "scenes"


@pytest.fixture()
def no_meshing(monkeypatch):
    """Any call into the meshers fails the test: refusals must come first."""
    from flexure import gmsh_mesh, meshing

    def boom(*a, **k):
        raise AssertionError("meshing started")

    monkeypatch.setattr(gmsh_mesh, "_session", boom)
    monkeypatch.setattr(meshing, "tetrahedralize", boom)


def _export(surf: Surface, path: Path) -> None:
    import trimesh

    trimesh.Trimesh(surf.points * 1e3, surf.faces, process=False).export(path)


def _design(tmp_path: Path, stl: str, gauges: list[dict], grid_mm=(1.5, 1.5)) -> Path:
    text = f'[geometry]\nkind = "stl"\nfile = "{stl}"\n[gauges]\ngrid_length_mm = {grid_mm[0]}\n' \
           f'grid_width_mm = {grid_mm[1]}\n'
    for g in gauges:
        text += "[[gauges.gauge]]\n" + "".join(f"{k} = {v!r}\n" for k, v in g.items())
    text += '[loads]\nload_radius_max_mm = 4.004\nfixed_radius_min_mm = 29.97\n[mesh]\nsize = "coarse"\n'
    p = tmp_path / "design.toml"
    p.write_text(text)
    return p


def _paper_gauges(**change) -> list[dict]:
    d = load_design(SCENES.parent / "designs" / "paper_disc.toml")
    out = [{"centre_mm": [float(x) * 1e3 for x in g.centre_m], "axis": [float(x) for x in g.axis], "arm": g.arm}
           for g in d.gauges]
    out[0].update(change)
    return out


@pytest.fixture()
def disc_stl(tmp_path):
    d = load_design(SCENES.parent / "designs" / "paper_disc.toml")
    _export(spoke_disc_surface(d.disc, 3), tmp_path / "disc.stl")
    return "disc.stl"


def _cli(capsys, path):
    code = main(["flexure", str(path), "--json"])
    out = capsys.readouterr()
    return code, out.out, out.err


def _boxes(*boxes):
    """Closed surface (m) of axis-aligned boxes given as (x0, y0, z0, x1, y1, z1) in mm."""
    import trimesh

    parts = [trimesh.creation.box(bounds=np.reshape(b, (2, 3)) * 1e-3) for b in boxes]
    tm = trimesh.util.concatenate(parts)
    return Surface(np.asarray(tm.vertices), np.asarray(tm.faces))


def test_valid_surface_and_gauges_pass_the_checks():
    """Positive control: the shipped disc and its four gauges raise nothing."""
    d = load_design(SCENES.parent / "designs" / "paper_disc.toml")
    s = spoke_disc_surface(d.disc, 3)
    check_solid(s.points, s.faces, "disc")
    check_gauges(s.points, s.faces, d.gauges, "disc")
    assert self_intersections(s.points, s.faces)[0] == 0


def test_self_intersecting_stl_exit_2(capsys, tmp_path, no_meshing):
    s = _boxes((0, 0, 0, 20, 20, 5), (10, 10, 2, 30, 30, 8))        # two overlapping closed boxes
    n, at = self_intersections(s.points, s.faces)
    assert n > 0 and np.all((at >= 0) & (at <= 0.03))
    _export(s, tmp_path / "x.stl")
    p = _design(tmp_path, "x.stl", [{"centre_mm": [5.0, 5.0, 5.0], "axis": [1.0, 0, 0], "arm": a} for a in (1, 2, 3, 4)])
    code, out, err = _cli(capsys, p)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "x.stl" in err and "intersects itself" in err


def test_separate_bodies_and_a_void_exit_2(capsys, tmp_path, no_meshing):
    """Two disjoint boxes (gmsh had meshed neither: "mesh: gmsh produced no tetrahedra", the file
    unnamed), and a box with a closed void inside: one line naming the file and the second piece."""
    gauges = [{"centre_mm": [5.0, 5.0, 5.0], "axis": [1.0, 0, 0], "arm": a} for a in (1, 2, 3, 4)]
    two = _boxes((0, 0, 0, 20, 20, 5), (30, 0, 0, 40, 10, 5))
    outer = _boxes((0, 0, 0, 20, 20, 5))
    void = _boxes((5, 5, 1, 15, 15, 4))
    hollow = Surface(np.vstack([outer.points, void.points]),
                     np.vstack([outer.faces, void.faces[:, ::-1] + len(outer.points)]))   # void wound inward
    for name, s, span in (("two.stl", two, "[30.0, 0.0, 0.0] to [40.0, 10.0, 5.0] mm"),
                          ("hollow.stl", hollow, "[5.0, 5.0, 1.0] to [15.0, 15.0, 4.0] mm")):
        _export(s, tmp_path / name)
        code, out, err = _cli(capsys, _design(tmp_path, name, gauges))
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert name in err and "2 separate pieces" in err and span in err


def test_zero_thickness_fin_exit_2(capsys, tmp_path, no_meshing):
    from shapely.geometry import box

    poly = box(0, 0, 0.02, 0.01).union(box(0.02, 0.0049995, 0.03, 0.0050005))    # a 1 µm fin
    s = extrude(poly, 0.005)
    t, at = thin_walls(s.points, s.faces, 1e-5)
    assert t == pytest.approx(1e-6, rel=1e-3) and at[0] > 0.02
    assert thin_walls(*(lambda q: (q.points, q.faces))(extrude(box(0, 0, 0.02, 0.01), 0.005)), 1e-5)[1] is None
    _export(s, tmp_path / "fin.stl")
    p = _design(tmp_path, "fin.stl", [{"centre_mm": [5.0, 5.0, 5.0], "axis": [1.0, 0, 0], "arm": a} for a in (1, 2, 3, 4)])
    code, out, err = _cli(capsys, p)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "fin.stl" in err and "zero-thickness" in err and "0.001 mm" in err


def test_open_stl_exit_2(capsys, tmp_path, no_meshing):
    import trimesh

    d = load_design(SCENES.parent / "designs" / "paper_disc.toml")
    s = spoke_disc_surface(d.disc, 3)
    tm = trimesh.Trimesh(s.points * 1e3, s.faces, process=False)
    tm.update_faces(tm.triangles_center[:, 2] < 2.2 - 1e-6)       # the whole top face gone
    tm.export(tmp_path / "open.stl")
    p = _design(tmp_path, "open.stl", _paper_gauges())
    code, out, err = _cli(capsys, p)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "open.stl" in err and "not watertight" in err


@pytest.mark.parametrize("change, needle", [
    ({"centre_mm": [11.0, 11.0, 2.2]}, "mm off the part's surface"),          # in the window between spokes
    ({"centre_mm": [15.5, 0.0, 1.1]}, "inside the part, not on its surface"),  # mid-thickness
    ({"centre_mm": [100.0, 0.0, 2.2]}, "off the part (outside its bounding box, 60 × 60 × 2.2 mm: is the file's length unit right?)"),
    ({"centre_mm": [15.5, 0.0, 2.2], "normal": [1.0, 0.0, 0.0], "axis": [0.0, 1.0, 0.0]}, "90° from the surface normal"),
    ({"centre_mm": [15.5, 1.2, 2.2]}, "overhangs its face"),                  # too near the spoke's edge
])
def test_misplaced_gauge_exit_2_names_the_gauge(capsys, tmp_path, disc_stl, no_meshing, change, needle):
    p = _design(tmp_path, disc_stl, _paper_gauges(**change))
    code, out, err = _cli(capsys, p)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert str(p) in err and "gauges: gauge g1 (arm 1)" in err and needle in err


def test_gauge_centre_nan_is_refused_by_the_schema(capsys, tmp_path, disc_stl, no_meshing):
    p = _design(tmp_path, disc_stl, _paper_gauges(centre_mm=[float("nan"), 0.0, 2.2]))
    code, out, err = _cli(capsys, p)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"{p}: gauges.gauge[1].centre_mm[1]: expected a finite number, got nan" in err


def test_gauge_larger_than_its_face_exit_2(capsys, tmp_path, disc_stl, no_meshing):
    """A 5 × 5 mm grid on a 3.5 mm spoke, explicit layout (the shear_45 layout refuses it itself)."""
    p = _design(tmp_path, disc_stl, _paper_gauges(), grid_mm=(5.0, 5.0))
    code, out, err = _cli(capsys, p)
    assert code == 2 and out == "" and "5 × 5 mm grid" in err and "overhangs its face" in err


def test_parametric_design_with_a_gauge_off_the_part(tmp_path, no_meshing):
    from flexure.analysis import analyze

    text = (SCENES.parent / "designs" / "paper_disc.toml").read_text().replace('sensor = "../sensors/paper_sensor.toml"', "")
    text = text.replace('layout = "shear_45"', 'layout = "explicit"')
    gauges = "".join(f"[[gauges.gauge]]\ncentre_mm = {g['centre_mm']}\naxis = {g['axis']}\narm = {g['arm']}\n"
                     for g in _paper_gauges(centre_mm=[40.0, 0.0, 2.2]))
    text = text.replace("[loads]", gauges + "[loads]")
    p = tmp_path / "d.toml"
    p.write_text(text)
    with pytest.raises(InputError, match=r"gauges: gauge g1 \(arm 1\): centre \[40.0, 0.0, 2.2\] mm"):
        analyze(load_design(p))


def _flipped_solids():
    """Closed solids with a third of their faces reversed (seeded): a sphere, a four-spoke disc
    (trimesh's extrusion), and the same two inside out."""
    import trimesh
    from shapely.geometry import Point

    rng = np.random.default_rng(11)
    from shapely.geometry import box

    disc = Point(0, 0).buffer(30).difference(Point(0, 0).buffer(22)).union(Point(0, 0).buffer(10))
    disc = disc.union(box(-26, -2, 26, 2)).union(box(-2, -26, 2, 26)).difference(Point(0, 0).buffer(4))
    for tm in (trimesh.creation.icosphere(3), trimesh.creation.extrude_polygon(disc.buffer(0), 4.0)):
        for inside_out in (False, True):
            f = np.asarray(tm.faces, np.int64)
            f = f[:, ::-1] if inside_out else f
            turn = rng.random(len(f)) < 1 / 3
            f = f.copy()
            f[turn] = f[turn][:, ::-1]
            yield np.asarray(tm.vertices, float), np.ascontiguousarray(f)


def test_orienting_faces_gives_trimeshs_winding():
    """geometry.orient_faces reverses the faces trimesh.repair.fix_normals reverses (the same
    arrays), on one-piece solids with faces turned; two pieces or an open surface: None."""
    import trimesh

    from flexure.geometry import orient_faces

    for points, faces in _flipped_solids():
        tm = trimesh.Trimesh(points, faces, process=False)
        assert not tm.is_winding_consistent
        trimesh.repair.fix_normals(tm)
        got = orient_faces(points, faces)
        assert got is not None and np.array_equal(got, np.asarray(tm.faces)) and tm.volume > 0
    two = trimesh.util.concatenate([trimesh.creation.box(), trimesh.creation.box().apply_translation([3, 0, 0])])
    assert orient_faces(np.asarray(two.vertices), np.asarray(two.faces)) is None
    box = trimesh.creation.box()
    assert orient_faces(np.asarray(box.vertices), np.asarray(box.faces)[1:]) is None


def test_compiled_box_sweep_gives_numpys_pairs(monkeypatch):
    """surface_check._box_pairs compiled: the same overlapping pairs in the same order as numpy."""
    from estimator import compiled

    from flexure import surface_check

    if not compiled.available():
        pytest.skip("numba not installed")
    rng = np.random.default_rng(2)
    lo = rng.uniform(0, 10, (3000, 3)) * [1, 1, 0.2]
    hi = lo + rng.uniform(0, 0.6, (3000, 3))
    got = {}
    for enabled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", enabled)
        pairs = list(surface_check._box_pairs(lo, hi))
        got[enabled] = [np.concatenate([p[k] for p in pairs]) for k in (0, 1)]
    assert len(got[True][0]) > 1000
    assert all(np.array_equal(a, b) for a, b in zip(got[True], got[False]))
