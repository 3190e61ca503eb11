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
