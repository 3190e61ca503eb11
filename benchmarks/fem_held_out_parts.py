"""Parts the adaptive FEM was checked on after its estimates and sizing were set (seventeenth and
eighteenth sessions), written to tests/data/fem_unseen/held_out/ with their design TOMLs:

    python benchmarks/fem_held_out_parts.py [NAME ...]

STEP parts drawn with gmsh's OpenCASCADE kernel (benchmarks/fem_unseen_parts.py's spoke disc), and
designer STLs drawn the way trimesh's docs show (``trimesh.creation.extrude_polygon``: earcut caps
of needle facets 50 mm long):

* four_thick.step: 7 mm thick, bore 3, hub 8, rim 20–25, four 3.5 mm spokes with sharp roots;
* tri_beam_thin.step: 2.2 mm thin, a 10 mm square hub, three 3 mm beams, a round frame 17–21 mm;
* five_needle.stl: 4.5 mm, rim 18.5–23, hub 7.5, five 3.2 mm spokes, bore 2.8, six 2 mm bolt holes in
  the rim (1.25 mm walls each side);
* holes8.stl: 6 mm, rim 22.8–26, hub 8, four 4.4 mm spokes, bore 3, eight 1.6 mm bolt holes in the rim
  (0.8 mm walls);
* sd3.stl, sd4.stl, sd6.stl: the spoke discs of tests/test_stl_remesh.py with 3, 4 and 6 spokes.

A third batch (twenty-first session), drawn and run before the gauge set's floor existed
(flexure.saturation.arm_floor); the floor was then chosen with its numbers in view, so it checks the run times
and the estimates as they were, not the floor independently:

* big_six.step: 80 mm across, 3 mm thin, six 5 mm spokes, 2 × 1.5 mm gauges, 10 N·m;
* side4.step: 6 mm, four 4 mm spokes, bending gauges on the spokes' side faces (normal ±y, axis radial);
* fillet3.step: 8 mm thick, three 4 mm spokes, 1 mm fillets at the rim, a chevron pair on each of two spokes;
* thin_cross.stl: 1.5 mm thin, a round hub, four 2.5 mm beams, a square frame with four bolt holes
  (gmsh's triangulation: an earcut extrusion of it leaves T-junctions, which the STL check rejects);
* hex_bore.stl: a designer STL (trimesh extrude), hexagonal bore coupled up to its corners, five spokes.

A fourth batch (twenty-second session), drawn and run on main 340e7ed before any change of that session:

* step_hub.step: a stepped part, an 8 mm hub (the bore's full height) under 4 mm spokes and rim, four 4 mm spokes;
* taper5.stl: a designer STL, five spokes tapering 5 → 2.5 mm from hub to rim;
* chunky3.step: small and thick, 10 mm thick and 30 mm across, three 3 mm spokes, arms 1–3 at 8.5 mm on the three
  spokes, arm 4 at 9.5 mm on arm 1's;
* wide8.step: thin (3 mm), eight 2 mm spokes, a 16 mm bore coupled at its wall, rim 26–30 mm;
* edge4.stl: gmsh's triangulation of a 3 mm four-spoke disc, radial gauges 0.9 mm off the spokes' centre lines
  (in-plane bending: arms 1, 3 stretched, 2, 4 compressed).

A fifth batch (twenty-third session), drawn by a seeded generator instead of by hand (``_random_discs``, seed
RANDOM_SEED) and run on main dea8a0f before anything else that session: rnd0 … rnd7, spoke discs with every
dimension drawn from a range (outer radius 15–40 mm, rim 2–6 mm, hub 0.2–0.35 of the outer radius, bore 0.3–0.7
of the hub, 3–8 spokes 1.5 mm to 0.7 of the hub's share of the circumference wide, 2–10 mm thick, a rim fillet
on a third of them, ±45° gauges at mid-spoke, 2–10 N·m), STEP and STL (gmsh's triangulation) in turn.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "fem_unseen" / "held_out"
sys.path.insert(0, str(ROOT / "benchmarks"))

import fem_unseen_parts as fu  # noqa: E402


def _gauges_same(z: float, where) -> str:
    """Gauges at (radius mm, angle °, axis offset °) on the top face z, arms 1–4 in turn."""
    out = []
    for arm, (radius, ang, off) in enumerate(where, start=1):
        a, ax = math.radians(ang), math.radians(ang + off)
        out.append(f"[[gauges.gauge]]\ncentre_mm = [{radius * math.cos(a):.6f}, {radius * math.sin(a):.6f}, {z:.6f}]\n"
                   f"axis = [{math.cos(ax):.9f}, {math.sin(ax):.9f}, 0.0]\narm = {arm}")
    return "\n".join(out)


def _extruded(poly, t: float, path: Path) -> None:
    import trimesh

    trimesh.creation.extrude_polygon(poly, t).export(path)


def _rim_disc(r_out, r_rim, r_hub, r_bore, spokes, holes, t, res=64):
    """Rim r_rim–r_out, hub, spokes [(x0, half width, x1, angle °)], bolt holes [(r, angle rad, radius, sides)]."""
    import shapely.affinity as sa
    import shapely.geometry as sg
    from shapely.ops import unary_union

    rim = sg.Point(0, 0).buffer(r_out, res).difference(sg.Point(0, 0).buffer(r_rim, res))
    arms = [sa.rotate(sg.box(x0, -w, x1, w), a, origin=(0, 0)) for x0, w, x1, a in spokes]
    poly = unary_union([rim, sg.Point(0, 0).buffer(r_hub, 48), *arms]).difference(sg.Point(0, 0).buffer(r_bore, 32))
    for r, a, rh, sides in holes:
        poly = poly.difference(sg.Point(r * math.cos(a), r * math.sin(a)).buffer(rh, sides))
    return poly


def _spoke_disc_stl(outer, rim, hub, bore, width, spokes, res=48):
    """tests/test_stl_remesh.py's spoke_disc (mm)."""
    import shapely.affinity as sa
    import shapely.geometry as sg
    from shapely.ops import unary_union

    ring = sg.Point(0, 0).buffer(outer, res).difference(sg.Point(0, 0).buffer(rim, res))
    hub_ = sg.Point(0, 0).buffer(hub, res).difference(sg.Point(0, 0).buffer(bore, res // 2))
    arms = [sa.rotate(sg.box(hub - 0.5, -width / 2, rim + 0.5, width / 2), a, origin=(0, 0))
            for a in [k * 360.0 / spokes for k in range(spokes)]]
    return unary_union([ring, hub_, *arms])


def _tri_beam(gmsh):
    occ, t = gmsh.model.occ, 2.2
    ring = occ.cut([(3, occ.addCylinder(0, 0, 0, 0, 0, t, 21))], [(3, occ.addCylinder(0, 0, 0, 0, 0, t, 17))])[0]
    hub = (3, occ.addBox(-5, -5, 0, 10, 10, t))
    beams = []
    for k in range(3):
        b = occ.addBox(3, -1.5, 0, 16, 3, t)
        occ.rotate([(3, b)], 0, 0, 0, 0, 0, 1, k * 2 * math.pi / 3)
        beams.append((3, b))
    body = occ.fuse(ring, [hub] + beams)[0]
    occ.cut(body, [(3, occ.addCylinder(0, 0, 0, 0, 0, t, 2.0))])
    occ.synchronize()


def _side_gauges(z: float, x: float, half_width: float) -> str:
    """Radial gauges on the side faces of the spokes along ±x, at x and half-height z: the faces that bending
    stretches alike for arms 1 and 3 (normals +y at +x, −y at −x) and compresses for 2 and 4."""
    rows = []
    for arm, (cx, cy) in enumerate([(x, half_width), (x, -half_width), (-x, -half_width), (-x, half_width)], start=1):
        rows.append(f"[[gauges.gauge]]\ncentre_mm = [{cx:.6f}, {cy:.6f}, {z:.6f}]\naxis = [1.0, 0.0, 0.0]\n"
                    f"normal = [0.0, {math.copysign(1.0, cy):.1f}, 0.0]\narm = {arm}")
    return "\n".join(rows)


def _fused_beams(occ, outer, hub, box, t: float, n: int = 4):
    """``outer`` fused with ``hub`` and n beams, box (x0, y0, length, width) of height t turned by 360°/n each."""
    x0, y0, length, width = box
    parts = [hub]
    for k in range(n):
        b = occ.addBox(x0, y0, 0, length, width, t)
        occ.rotate([(3, b)], 0, 0, 0, 0, 0, 1, k * 2 * math.pi / n)
        parts.append((3, b))
    return occ.fuse(outer, parts)[0]


def _step_hub(gmsh):
    occ = gmsh.model.occ
    t, th = 4.0, 8.0
    ring = occ.cut([(3, occ.addCylinder(0, 0, 0, 0, 0, t, 25))], [(3, occ.addCylinder(0, 0, 0, 0, 0, t, 20))])[0]
    body = _fused_beams(occ, ring, (3, occ.addCylinder(0, 0, 0, 0, 0, th, 8)), (4, -2, 18.5, 4), t)
    occ.cut(body, [(3, occ.addCylinder(0, 0, 0, 0, 0, th, 3))])
    occ.synchronize()


def _taper5():
    import shapely.geometry as sg
    from shapely.ops import unary_union

    rim = sg.Point(0, 0).buffer(23, 64).difference(sg.Point(0, 0).buffer(19, 64))
    arms = []
    for k in range(5):
        c, s = math.cos(2 * math.pi * k / 5), math.sin(2 * math.pi * k / 5)
        arms.append(sg.Polygon([(x * c - y * s, x * s + y * c) for x, y in [(6, -2.5), (20, -1.25), (20, 1.25), (6, 2.5)]]))
    return unary_union([rim, sg.Point(0, 0).buffer(7, 48), *arms]).difference(sg.Point(0, 0).buffer(2.5, 32))


def _edge_gauges(z: float) -> str:
    """Radial gauges on the top face z of the spokes along ±x, 0.9 mm each side of their centre lines."""
    rows = []
    for arm, (x, y) in enumerate([(12.0, 0.9), (12.0, -0.9), (-12.0, -0.9), (-12.0, 0.9)], start=1):
        rows.append(f"[[gauges.gauge]]\ncentre_mm = [{x:.6f}, {y:.6f}, {z:.6f}]\naxis = [1.0, 0.0, 0.0]\narm = {arm}")
    return "\n".join(rows)


def _thin_cross(gmsh):
    occ, t = gmsh.model.occ, 1.5
    frame = occ.cut([(3, occ.addBox(-22, -22, 0, 44, 44, t))], [(3, occ.addBox(-18, -18, 0, 36, 36, t))])[0]
    body = _fused_beams(occ, frame, (3, occ.addCylinder(0, 0, 0, 0, 0, t, 6)), (5, -1.25, 14, 2.5), t)
    bore = [(3, occ.addCylinder(0, 0, 0, 0, 0, t, 2.5))]
    occ.cut(body, bore + [(3, occ.addCylinder(20 * sx, 20 * sy, 0, 0, 0, t, 1.2)) for sx in (-1, 1) for sy in (-1, 1)])
    occ.synchronize()


def _hex_bore():
    import shapely.geometry as sg

    hexagon = sg.Polygon([(3.5 * math.cos(math.pi / 3 * k), 3.5 * math.sin(math.pi / 3 * k)) for k in range(6)])
    return _rim_disc(26, 21, 9, 0.1, [(6, 1.75, 23.0, 72 * k + 36) for k in range(5)], [], 5.0).difference(hexagon)


PARTS = {
    "four_thick": dict(kind="step", about="thick four-spoke STEP, sharp roots",
                       build=lambda g: fu._spoke_disc(g, 7.0, 3.0, 8.0, 20.0, 25.0, 4, 3.5), L=1.0, W=1.0, T=4.0,
                       load_r=3.02, fixed_r=24.95, gauges=lambda: fu._gauges(7.0, ((13, 0), (13, 90), (13, 180), (13, 270)))),
    "tri_beam_thin": dict(kind="step", about="thin three-beam square-hub STEP", build=_tri_beam, L=1.2, W=0.8, T=1.5,
                          load_r=2.02, fixed_r=17.05,
                          gauges=lambda: fu._gauges(2.2, ((9.5, 0.0), (12.5, 0.0), (9.5, 120.0), (12.5, 120.0)))),
    "five_needle": dict(kind="stl", about="designer STL (trimesh extrude, needle caps), five spokes, bolt holes",
                        poly=lambda: _rim_disc(23, 18.5, 7.5, 2.8, [(4.0, 1.6, 20.0, 72 * k) for k in range(5)],
                                               [(20.75, 2 * math.pi * k / 6 + 0.3, 1.0, 16) for k in range(6)], 4.5),
                        t=4.5, L=1.0, W=0.8, T=3.0, load_r=2.82, fixed_r=18.55,
                        gauges=lambda: fu._gauges(4.5, ((12.0, 0.0), (12.0, 72.0), (12.0, 144.0), (12.0, 216.0)))),
    "holes8": dict(kind="stl", about="designer STL, four spokes, eight 1.6 mm bolt holes in a 3.2 mm rim",
                   poly=lambda: _rim_disc(26, 22.8, 8, 3.0, [(6, 2.2, 23.5, 90 * k + 45) for k in range(4)],
                                          [(24.4, 2 * math.pi * k / 8, 0.8, 12) for k in range(8)], 6.0),
                   t=6.0, L=1.0, W=0.8, T=5.0, load_r=3.02, fixed_r=22.85,
                   gauges=lambda: _gauges_same(6.0, [(15.0, a, 45) for a in (45, 135, 225, 315)])),
    "sd4": dict(kind="stl", about="designer STL spoke disc, 4 spokes", poly=lambda: _spoke_disc_stl(30, 25, 9, 3, 4, 4),
                t=5.0, L=1.0, W=0.8, T=4.0, load_r=3.02, fixed_r=25.05,
                gauges=lambda: _gauges_same(5.0, [(17.0, a, 45) for a in (0, 90, 180, 270)])),
    "sd3": dict(kind="stl", about="designer STL spoke disc, 3 spokes", poly=lambda: _spoke_disc_stl(22, 18, 7, 2.5, 3, 3),
                t=4.0, L=1.0, W=0.8, T=2.0, load_r=2.52, fixed_r=18.05,
                gauges=lambda: _gauges_same(4.0, [(12.5, 0, 45), (12.5, 120, 45), (12.5, 240, 45), (14.5, 0, -45)])),
    "sd6": dict(kind="stl", about="designer STL spoke disc, 6 spokes",
                poly=lambda: _spoke_disc_stl(25, 21, 8, 3, 3, 6, res=32), t=3.0, L=1.0, W=0.8, T=2.0,
                load_r=3.02, fixed_r=21.05, gauges=lambda: _gauges_same(3.0, [(14.5, a, 45) for a in (0, 60, 120, 180)])),
    "big_six": dict(kind="step", about="large thin six-spoke STEP (80 mm)", L=2.0, W=1.5, T=10.0, load_r=4.02,
                    build=lambda g: fu._spoke_disc(g, 3.0, 4.0, 10.0, 34.0, 40.0, 6, 5.0), fixed_r=39.95,
                    gauges=lambda: fu._gauges(3.0, ((22, 0), (22, 60), (22, 120), (22, 180)))),
    "side4": dict(kind="step", about="four-spoke STEP, bending gauges on the spokes' side faces", L=2.0, W=1.0, T=4.0,
                  build=lambda g: fu._spoke_disc(g, 6.0, 3.0, 8.0, 20.0, 25.0, 4, 4.0), load_r=3.02, fixed_r=24.95,
                  gauges=lambda: _side_gauges(3.0, 10.5, 2.0)),
    "fillet3": dict(kind="step", about="thick three-spoke STEP, rim fillets", L=1.0, W=1.0, T=4.0, load_r=3.02,
                    build=lambda g: fu._spoke_disc(g, 8.0, 3.0, 7.0, 17.0, 22.0, 3, 4.0, rim_fillet=1.0), fixed_r=21.95,
                    gauges=lambda: fu._gauges(8.0, ((11, 0), (13, 0), (11, 120), (13, 120)))),
    "thin_cross": dict(kind="stl", about="thin cross with a holed square frame, an STL of gmsh's triangulation",
                       build=_thin_cross, L=1.0, W=0.8, T=1.0, load_r=2.52, fixed_r=21.95,
                       gauges=lambda: fu._gauges(1.5, ((11, 0), (11, 90), (11, 180), (11, 270)))),
    "hex_bore": dict(kind="stl", about="designer STL, hex bore, five spokes", poly=_hex_bore, t=5.0, L=1.0, W=0.8,
                     T=4.0, load_r=3.52, fixed_r=21.05, gauges=lambda: fu._gauges(5.0, ((14, 36), (14, 108), (14, 180), (14, 252)))),
    "step_hub": dict(kind="step", about="stepped STEP: an 8 mm hub, 4 mm spokes and rim, four 4 mm spokes", build=_step_hub,
                     L=1.0, W=1.0, T=4.0, load_r=3.02, fixed_r=24.95,
                     gauges=lambda: fu._gauges(4.0, ((14, 0), (14, 90), (14, 180), (14, 270)))),
    "taper5": dict(kind="stl", about="designer STL, five tapered spokes", poly=_taper5, t=4.0, L=1.0, W=0.8, T=3.0,
                   load_r=2.52, fixed_r=19.05, gauges=lambda: fu._gauges(4.0, ((13, 0), (13, 72), (13, 144), (13, 216)))),
    "chunky3": dict(kind="step", about="small thick three-spoke STEP (10 mm thick, 30 mm across)",
                    build=lambda g: fu._spoke_disc(g, 10.0, 2.0, 5.0, 12.0, 15.0, 3, 3.0), L=1.0, W=1.0, T=6.0,
                    load_r=2.02, fixed_r=14.95, gauges=lambda: fu._gauges(10.0, ((8.5, 0), (8.5, 120), (8.5, 240), (9.5, 0)))),
    "wide8": dict(kind="step", about="thin eight-spoke STEP with a 16 mm bore", L=1.0, W=0.8, T=6.0, load_r=8.02,
                  build=lambda g: fu._spoke_disc(g, 3.0, 8.0, 12.0, 26.0, 30.0, 8, 2.0), fixed_r=29.95,
                  gauges=lambda: fu._gauges(3.0, ((19, 0), (19, 45), (19, 90), (19, 135)))),
    "edge4": dict(kind="stl", about="gmsh STL, four spokes, radial gauges off the spokes' centre lines",
                  build=lambda g: fu._spoke_disc(g, 3.0, 2.0, 6.0, 18.0, 22.0, 4, 3.0), L=1.0, W=0.6, T=2.0,
                  load_r=2.02, fixed_r=21.95, gauges=lambda: _edge_gauges(3.0)),
}

#: the fifth batch's generator seed (``_random_discs``)
RANDOM_SEED = 2311


def _random_discs(seed: int = RANDOM_SEED, n: int = 8) -> dict:
    """``n`` spoke discs (module docstring, fifth batch) drawn by ``random.Random(seed)``: PARTS entries rnd0 …"""
    import random

    rng = random.Random(seed)
    parts = {}
    for i in range(n):
        r_out = rng.uniform(15, 40)
        rim = rng.uniform(2, 6)
        r_rim_in = r_out - rim
        r_hub = rng.uniform(0.2, 0.35) * r_out
        r_bore = rng.uniform(0.3, 0.7) * r_hub
        spokes = rng.randint(3, 8)
        width = rng.uniform(1.5, max(1.6, min(6.0, 0.7 * 2 * math.pi * r_hub / spokes)))
        t = rng.uniform(2, 10)
        fillet = rng.choice([0.0, 0.0, min(1.0, 0.3 * width)])
        L = round(min(2.0, max(0.8, 0.6 * width)), 2)
        r_g = 0.5 * (r_hub + r_rim_in)           # mid-spoke; with three spokes arm 4 further out on the first
        on = [0, 1, 2, 3] if spokes >= 4 else [0, 1, 2, 0]
        where = [(r_g if k < 3 or spokes >= 4 else r_g + 0.25 * (r_rim_in - r_hub), 360.0 * s / spokes)
                 for k, s in enumerate(on)]
        dims = (t, r_bore, r_hub, r_rim_in, r_out, spokes, width)
        parts[f"rnd{i}"] = dict(
            kind="step" if i % 2 == 0 else "stl",
            about=f"random spoke disc {i} (seed {seed}): t {t:.1f}, r_out {r_out:.1f}, rim {rim:.1f}, hub {r_hub:.1f}, "
                  f"bore {r_bore:.1f}, n {spokes}, width {width:.2f}, fillet {fillet:.2f}",
            build=lambda g, d=dims, f=fillet: fu._spoke_disc(g, *d, rim_fillet=f), L=L, W=round(0.8 * L, 2),
            T=round(rng.uniform(2, 10), 1), load_r=round(r_bore + 0.02, 3), fixed_r=round(r_out - 0.05, 3),
            gauges=lambda z=t, w=where: fu._gauges(z, w))
    return parts


PARTS.update(_random_discs())


def write(name: str) -> Path:
    p = PARTS[name]
    OUT.mkdir(parents=True, exist_ok=True)
    geo = OUT / f"{name}.{p['kind']}"
    if "build" in p:
        fu.write_geometry(p["build"], geo)
    else:
        _extruded(p["poly"](), p["t"], geo)
    return fu.write_toml(OUT, name, p, geo.name, "fem_held_out_parts.py")


if __name__ == "__main__":
    sys.exit(fu.main(sys.argv[1:], PARTS, write))
