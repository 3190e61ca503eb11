"""The skew annulus test part: a 2 mm annulus (r 3 … 10 mm) STL with four gauges at unequal radii and
skewed axes (no symmetry: the off-axis load cases give every gauge a reading), shared by the FEM
tests (test_fem_goal_cases, test_adaptive_speed)."""

import math

from flexure.design import load_design

PART = """\
name = "skew_annulus"
[geometry]
kind = "stl"
file = "annulus.stl"
[gauges]
grid_length_mm = 1.5
grid_width_mm = 1.0
{gauges}
[loads]
rated_torque_Nm = 2.0
load_radius_max_mm = 3.02
fixed_radius_min_mm = {fixed_min}
[mesh]
size = "coarse"
order = 2
"""


def skew_annulus(tmp, sections: int = 48, fixed_min_mm: float = 9.9):
    """A 2 mm annulus (r 3 … 10 mm, polygons of ``sections`` sides) STL, four gauges at unequal radii
    with skewed axes (no symmetry), clamped at r ≥ ``fixed_min_mm``."""
    import trimesh

    tm = trimesh.creation.annulus(r_min=3.0, r_max=10.0, height=2.0, sections=sections)
    tm.apply_translation((0, 0, 1.0))
    tm.export(tmp / "annulus.stl")
    gauges = []
    for arm, (r, ang, off) in enumerate([(5.0, 17.0, 30.0), (6.0, 131.0, 55.0), (7.0, 208.0, -40.0),
                                         (8.0, 303.0, -65.0)], start=1):
        a, o = math.radians(ang), math.radians(ang + off)
        gauges.append(f"[[gauges.gauge]]\ncentre_mm = [{r * math.cos(a):.6f}, {r * math.sin(a):.6f}, 2.0]\n"
                      f"axis = [{math.cos(o):.9f}, {math.sin(o):.9f}, 0.0]\narm = {arm}")
    (tmp / "skew.toml").write_text(PART.format(gauges="\n".join(gauges), fixed_min=fixed_min_mm))
    return load_design(tmp / "skew.toml")
