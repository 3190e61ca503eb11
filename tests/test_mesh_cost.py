"""The mesh-cost estimate that refuses hopeless meshes before meshing (flexure.meshing.check_cost)
is close to the element count the mesher then makes, on parametric, STL and STEP parts."""

from pathlib import Path

import pytest

import flexure.meshing as M
from flexure.analysis import build_mesh
from flexure.design import load_design

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.parametrize("design, h_factor", [
    ("designs/paper_disc.toml", 1.0),
    ("tests/data/fem_reference/thick_disc.toml", 0.5),           # 5 mm thick, 0.15 mm at the gauges
    ("tests/data/fem_reference/thick_disc_stl.toml", 1.0),
    ("tests/data/fem_reference/step_part.toml", 0.5),
])
def test_element_estimate_is_within_2x_of_the_mesh_made(monkeypatch, design, h_factor):
    seen = []
    check = M.check_cost

    def spy(*args, **kw):
        seen.append(check(*args, **kw))
        return seen[-1]

    monkeypatch.setattr(M, "check_cost", spy)
    mesh = build_mesh(load_design(ROOT / design), order=1, h_factor=h_factor).mesh
    made = len(mesh.corner_tets)
    assert len(seen) == 1
    print(f"{design} h x {h_factor}: estimate {seen[0]:.3g}, made {made}")
    assert 0.5 < seen[0] / made < 2.0, (seen[0], made)


def _design(tmp_path, **replace):
    """The shipped paper disc with some of its [geometry] lines replaced (mm)."""
    src = ROOT / "designs" / "paper_disc.toml"
    text = src.read_text().replace('sensor = "../sensors/paper_sensor.toml"',
                                   f'sensor = "{ROOT / "sensors" / "paper_sensor.toml"}"')
    lines = []
    for line in text.splitlines():
        key = line.split("=")[0].strip()
        lines.append(f"{key} = {replace[key]}" if key in replace else line)
    p = tmp_path / "hostile.toml"
    p.write_text("\n".join(lines) + "\n")
    return p


@pytest.fixture
def no_meshing(monkeypatch):
    """Every mesher fails the test if it is called: the refusal comes from the estimate alone."""
    from flexure import gmsh_mesh, stl_remesh

    def refuse(*a, **k):
        raise AssertionError("a mesher was called before the cost estimate refused")

    for mod, name in ((gmsh_mesh, "_session"), (stl_remesh, "mesh_surface"), (M, "tetrahedralize"),
                      (M, "sweep_mesh"), (M, "mesh_design_surface")):
        monkeypatch.setattr(mod, name, refuse)


@pytest.mark.parametrize("replace, key", [
    # 4 m tall: its volume term alone passes (h ≤ the part's own 2V/A ≈ 7 mm), but each bolt hole's
    # wall, meshed at 2πR/8.5 by gmsh's curvature sizing, is millions of tetrahedra
    ({"thickness_mm": "4000"}, "geometry.thickness_mm = 4000 mm"),
    # a 60 mm thick disc whose spoke roots carry 0.05 mm fillets
    ({"thickness_mm": "60", "fillet_radius_mm": "0.05"}, "geometry.fillet_radius_mm"),
])
def test_hostile_design_refused_from_its_geometry_before_meshing(tmp_path, capsys, no_meshing, replace, key):
    """exit 2, one line: the key, the predicted element count and memory, the flag that raises the budget."""
    from torquebench.cli import main

    code = main(["flexure", str(_design(tmp_path, **replace))])
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert code == 2 and len(err) == 1, err
    assert key in err[0] and "tetrahedra" in err[0] and "GB" in err[0] and "--max-elements" in err[0]


def test_curved_walls_add_to_the_estimate_where_gmsh_refines_them():
    """The paper disc: its bolt holes and fillets add elements at h × 1 (gmsh sizes curved faces at
    2πR / curvature_elements), and a wall 100× taller adds 100× as many there; no curvature sizing
    (curvature_elements = 0): no wall term."""
    from dataclasses import replace

    from flexure.design import curved_walls, load_design
    from flexure.sizing import estimate_parts

    d = load_design(ROOT / "designs" / "paper_disc.toml")
    field = M.size_field("coarse", d.disc.thickness, [[0.0, 0.0, 0.0]], 1e-3, 1e-3)
    walls = curved_walls(d.disc)
    parts = estimate_parts(field, 1e-6, d.disc.thickness, walls)
    tall = estimate_parts(field, 1e-6, d.disc.thickness, [(k, r, 100 * h, a, o) for k, r, h, a, o in walls])
    assert parts["geometry.hub_bolt_diameter_mm"] > 0
    assert tall["geometry.hub_bolt_diameter_mm"] == pytest.approx(100 * parts["geometry.hub_bolt_diameter_mm"])
    flat = estimate_parts(replace(field, curvature_elements=0.0), 1e-6, d.disc.thickness, walls)
    assert set(flat) == {"volume", "gauges", "edges"}


def test_hostile_step_refused_before_its_surface_is_meshed(tmp_path, capsys):
    """A 300 × 300 × 0.2 mm STEP plate: the estimate from the solid's volume and area refuses it
    before gmsh triangulates its surface (at 0.2 mm that alone is millions of triangles)."""
    import gmsh

    from flexure.gmsh_session import _quiet_stdout
    from torquebench.cli import main

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.occ.addBox(-150, -150, 0, 300, 300, 0.2)
        gmsh.model.occ.synchronize()
        with _quiet_stdout():
            gmsh.write(str(tmp_path / "plate.step"))
    finally:
        gmsh.finalize()
    sensor = ROOT / "sensors" / "paper_sensor.toml"
    (tmp_path / "plate.toml").write_text(
        'name = "plate"\n[geometry]\nkind = "step"\nfile = "plate.step"\n[gauges]\ngrid_length_mm = 1.0\n'
        'grid_width_mm = 1.0\n' + "".join(
            f"[[gauges.gauge]]\ncentre_mm = [{x}, {y}, 0.2]\naxis = [0.7071067812, 0.7071067812, 0.0]\narm = {i}\n"
            for i, (x, y) in enumerate(((20, 0), (0, 20), (-20, 0), (0, -20)), 1))
        + f'[loads]\nrated_torque_Nm = 2.0\nload_radius_max_mm = 5.0\nfixed_radius_min_mm = 140.0\n'
          f'[bridge]\nsensor = "{sensor}"\n')
    code = main(["flexure", str(tmp_path / "plate.toml")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert code == 2 and len(err) == 1, err
    assert "plate.step" in err[0] and "tetrahedra" in err[0] and "GB" in err[0] and "--max-elements" in err[0]
