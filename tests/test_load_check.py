"""Hold and load radii against the part, checked before meshing (flexure.load_check): a user's
STL made the obvious way (trimesh.creation.extrude_polygon of a hub–spokes–ring disc), a hold
radius beyond the part or a load radius inside its bore → exit 2 with one line naming the key
the user wrote, and no mesher is ever called."""

import numpy as np
import pytest

from torquebench.cli import main

#: ±45° gauges at mid-spoke on the top face, axes alternating so that the bridge reads torque
GAUGES = "\n".join(f"[[gauges.gauge]]\ncentre_mm = [{x}, {y}, 5.0]\naxis = [{ax}, {ay}, 0.0]\narm = {arm}"
                   for arm, (x, y, ax, ay) in enumerate(((16.5, 0, 0.7071067812, -0.7071067812),
                                                        (0, 16.5, -0.7071067812, 0.7071067812),
                                                        (-16.5, 0, -0.7071067812, 0.7071067812),
                                                        (0, -16.5, 0.7071067812, -0.7071067812)), 1))


def disc_stl(path, outer=30.0, rim=24.0, hub=9.0, bore=4.0, width=4.0, thick=5.0):
    """A hub–spokes–ring disc as a designer would build it with trimesh (mm)."""
    import trimesh
    from shapely import affinity
    from shapely.geometry import Point, box
    from shapely.ops import unary_union

    ring = Point(0, 0).buffer(outer, 64).difference(Point(0, 0).buffer(rim, 64))
    hub_ = Point(0, 0).buffer(hub, 64).difference(Point(0, 0).buffer(bore, 32))
    spokes = [affinity.rotate(box(hub - 1, -width / 2, rim + 1, width / 2), a, origin=(0, 0))
              for a in (0, 90, 180, 270)]
    trimesh.creation.extrude_polygon(unary_union([ring, hub_, *spokes]), thick).export(path)
    return path


def design(tmp_path, loads: str):
    disc_stl(tmp_path / "disc.stl")
    p = tmp_path / "disc.toml"
    p.write_text(f'name = "my_disc"\n[geometry]\nkind = "stl"\nfile = "disc.stl"\n'
                 f"[gauges]\ngrid_length_mm = 1.0\ngrid_width_mm = 1.0\n{GAUGES}\n"
                 f"[loads]\nrated_torque_Nm = 2.0\n{loads}\n[mesh]\nsize = \"coarse\"\norder = 2\n")
    return p


@pytest.fixture
def no_meshing(monkeypatch):
    """Every mesher fails the test if it is called."""
    from flexure import gmsh_mesh, meshing, stl_remesh

    def refuse(*a, **k):
        raise AssertionError("a mesher was called before the geometry check")

    for mod, name in ((stl_remesh, "mesh_surface"), (gmsh_mesh, "_session"), (meshing, "tetrahedralize"),
                      (meshing, "sweep_mesh"), (meshing, "mesh_design_surface")):
        monkeypatch.setattr(mod, name, refuse)


@pytest.mark.parametrize("loads, key, value", [
    ("load_radius_max_mm = 4.05\nfixed_radius_min_mm = 35.0", "loads.fixed_radius_min_mm = 35 mm", "30 mm"),
    ("load_radius_max_mm = 2.5\nfixed_radius_min_mm = 29.0", "loads.load_radius_max_mm = 2.5 mm", "r = 3.9"),
])
def test_radius_off_the_part_refused_before_meshing_naming_the_users_key(tmp_path, capsys, no_meshing,
                                                                          loads, key, value):
    code = main(["flexure", str(design(tmp_path, loads))])
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert code == 2
    assert len(err) == 1 and key in err[0] and value in err[0], err
    assert "loads.fixed:" not in err[0]


def test_radii_on_the_part_pass_the_check(tmp_path):
    """The same part with radii it has: no refusal (the check is exact, not a heuristic)."""
    from flexure.design import load_design
    from flexure.geometry import load_stl
    from flexure.load_check import axis_distance_range, check_loads

    d = load_design(design(tmp_path, "load_radius_max_mm = 4.05\nfixed_radius_min_mm = 29.95"))
    surf = load_stl(d.file_path, d.file_unit_m)
    r_min, r_max = axis_distance_range(surf.points, surf.faces)
    # the bore is a 128-gon of radius 4 (trimesh/shapely: 32 segments per quarter): its
    # flats reach in to 4 cos(π/128); the outer 256-gon's corners reach 30
    assert r_min == pytest.approx(4e-3 * np.cos(np.pi / 128), rel=1e-6)   # an STL stores float32
    assert r_max == pytest.approx(30e-3, rel=1e-6)   # an STL stores float32
    check_loads(d, surf)


def test_axis_covered_by_a_solid_centre():
    """A face whose projection covers the axis: r_min = 0 (a solid hub can be loaded anywhere)."""
    from flexure.load_check import axis_distance_range

    pts = np.array([[-1, -1, 0], [2, -1, 0], [-1, 2, 0], [5, 5, 1]], float)
    assert axis_distance_range(pts, np.array([[0, 1, 2], [0, 1, 3]]))[0] == 0.0
    assert axis_distance_range(pts + [3, 3, 0], np.array([[0, 1, 2]]))[0] == pytest.approx(np.hypot(2, 2) / 1)
