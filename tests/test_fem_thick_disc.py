"""The issue-13 thick disc (4 straight spokes, no fillets, 5 mm thick, 0.5 × 0.5 mm ±45° gauges at
mid-spoke), parametric and as an STL, through the default (gmsh, graded) mesher."""

from pathlib import Path

import numpy as np
import pytest

from flexure.analysis import analyze
from flexure.design import load_design

SCENES = Path(__file__).resolve().parents[1] / "scenes"
DATA = Path(__file__).resolve().parent / "data" / "fem_reference"


def _thick_text() -> str:
    t = (SCENES.parent / "designs" / "paper_disc.toml").read_text()
    for a, b in (("thickness_mm = 2.2 ", "thickness_mm = 5.0 "), ("fillet_radius_mm = 1.5 ", "fillet_radius_mm = 0.0 "),
                 ("grid_length_mm = 1.5", "grid_length_mm = 0.5"), ("grid_width_mm = 1.5", "grid_width_mm = 0.5"),
                 ('sensor = "../sensors/paper_sensor.toml"', f'sensor = "{SCENES.parent / "sensors" / "paper_sensor.toml"}"')):
        assert a in t
        t = t.replace(a, b)
    return t


@pytest.fixture(scope="module")
def thick(tmp_path_factory):
    p = tmp_path_factory.mktemp("thick") / "thick.toml"
    p.write_text(_thick_text())
    d = load_design(p)
    res, _ = analyze(d)
    return d, res


@pytest.mark.slow       # 31 s of CPU; in the default run the paper disc's default mesh is checked for
# slivers (test_flexure_design.test_mesh_quality_report_and_refinement_at_the_gauges) and its arms
# for balance (test_flexure_design.test_crosstalk_of_a_symmetric_layout_cancels)
def test_thick_disc_default_mesh_has_no_slivers_and_balanced_arms(thick):
    _, res = thick
    m = res["mesh"]
    assert m["mesher"] == "gmsh" and m["n_slivers"] == 0 and m["min_dihedral_deg"] > 5.0
    assert res["gauge_arm_imbalance"] < 0.02              # four-fold symmetric part: arms agree


@pytest.mark.slow
def test_thick_disc_as_stl_agrees_arm_to_arm_and_with_the_parametric_one(thick):
    """The same disc as an STL of its polygonal outline (tests/data/fem_reference/thick_disc.stl,
    written by flexure.geometry.spoke_disc_surface(disc, 3)), re-meshed by gmsh, held at its whole
    outer face."""
    d, res = thick
    r, _ = analyze(load_design(DATA / "thick_disc_stl.toml"))
    assert r["mesh"]["mesher"] == "gmsh" and abs(r["mesh"]["remesh_volume_change"]) < 0.01
    # tetgen on the raw STL gave ±25 %. The four arms now agree to 0.60 % at this level (h × 1,
    # `analyze`'s single level), 0.36 % at h × √2 and 0.55 % at h × 1/√2 (the answer of the default
    # three-level run; tests/data/fem_reference/levels.json); before the re-entrant spoke roots were
    # refined (flexure.meshing.reentrant_edges) it was 2.57 %, 2.51 % and 1.34 %.
    assert r["gauge_arm_imbalance"] < 0.02
    # held at the outer face instead of the bolt holes: compare the spoke strain only
    assert r["gauge_strain_per_Nm"] == pytest.approx(res["gauge_strain_per_Nm"], rel=0.05)
    assert np.isfinite(r["torsional_stiffness_Nm_per_rad"])
