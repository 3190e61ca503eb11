"""Parts the FEM's estimates were not tuned on, drawn here with gmsh's OpenCASCADE kernel, written to
tests/data/fem_unseen/ (STEP and STL, with their design TOMLs):

    python benchmarks/fem_unseen_parts.py

* three_spoke_thin.step: 1.6 mm thin, three 3 mm spokes with sharp (unfilleted) roots at hub and
  rim, a 3 mm bore, two chevron pairs of 1 × 1 mm gauges on two spokes, held at the outer face;
* six_spoke_thick.stl: 6 mm thick, six 2.5 mm spokes, 0.6 mm fillets at the rim only, triangulated
  by gmsh (≤ 1.5 mm, 16 per turn; binary): an STL, its facets the geometry; gauges 0.8 × 0.8 mm at
  mid-spoke;
* cross_frame.step: a square hub, four beams and a square frame (sharp inner corners everywhere),
  5 mm thick, gauges 1.5 × 1 mm on the beams, held at the frame's outer faces (r ≥ 19.95 mm: the
  whole outer square, r = 20 … 28.3 mm).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "fem_unseen"

HEADER = """# {about}
# Made by benchmarks/fem_unseen_parts.py (not tuned on: the estimates' cross-check, benchmarks/fem_effectivity.py).
name = "{name}"

[geometry]
kind = "{kind}"
file = "{file}"

[gauges]
grid_length_mm = {L}
grid_width_mm = {W}
{gauges}

[loads]
rated_torque_Nm = {T}
load_radius_max_mm = {load_r}
fixed_radius_min_mm = {fixed_r}

[mesh]
size = "coarse"
order = 2
"""


def _gauges(z: float, where) -> str:
    """±45° gauges on the top face z, at (radius mm, spoke angle °) each; arms 1–4 alternate the
    ±45° so that the full bridge adds them (ε1 − ε2 + ε3 − ε4)."""
    out = []
    for arm, (radius, ang) in zip((1, 2, 3, 4), where):
        a = math.radians(ang)
        s = 1 if arm % 2 else -1
        ax = (math.cos(a + s * math.pi / 4), math.sin(a + s * math.pi / 4))
        out.append(f"[[gauges.gauge]]\ncentre_mm = [{radius * math.cos(a):.6f}, {radius * math.sin(a):.6f}, {z:.6f}]\n"
                   f"axis = [{ax[0]:.9f}, {ax[1]:.9f}, 0.0]\narm = {arm}")
    return "\n".join(out)


def _spoke_disc(gmsh, t, r_bore, r_hub, r_rim_in, r_out, n, width, rim_fillet=0.0):
    occ = gmsh.model.occ
    ring = occ.cut([(3, occ.addCylinder(0, 0, 0, 0, 0, t, r_out))], [(3, occ.addCylinder(0, 0, 0, 0, 0, t, r_rim_in))])[0]
    parts = [(3, occ.addCylinder(0, 0, 0, 0, 0, t, r_hub))]
    for k in range(n):
        b = occ.addBox(0.5 * r_hub, -width / 2, 0, 0.5 * (r_rim_in + r_out) - 0.5 * r_hub, width, t)
        occ.rotate([(3, b)], 0, 0, 0, 0, 0, 1, 2 * math.pi * k / n)
        parts.append((3, b))
    body = occ.fuse(ring, parts)[0]
    occ.synchronize()
    if rim_fillet > 0:
        edges = []
        for _, c in gmsh.model.getEntities(1):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(1, c)
            r = math.hypot(0.5 * (x0 + x1), 0.5 * (y0 + y1))
            if max(x1 - x0, y1 - y0) < 1e-6 and abs(z1 - z0 - t) < 1e-6 and abs(r - r_rim_in) < 0.6 * width:
                edges.append(c)
        body = occ.fillet([body[0][1]], edges, [rim_fillet], removeVolume=True)
        occ.synchronize()
    occ.cut(body, [(3, occ.addCylinder(0, 0, 0, 0, 0, t, r_bore))])
    occ.synchronize()


def three_spoke_thin(gmsh):
    _spoke_disc(gmsh, 1.6, 1.5, 5.0, 16.0, 20.0, 3, 3.0)


def six_spoke_thick(gmsh):
    _spoke_disc(gmsh, 6.0, 2.5, 7.0, 18.0, 22.0, 6, 2.5, rim_fillet=0.6)


def cross_frame(gmsh):
    occ = gmsh.model.occ
    t = 5.0
    frame = occ.cut([(3, occ.addBox(-20, -20, 0, 40, 40, t))], [(3, occ.addBox(-16, -16, 0, 32, 32, t))])[0]
    hub = (3, occ.addBox(-5, -5, 0, 10, 10, t))
    beams = [(3, occ.addBox(4, -2, 0, 13, 4, t))]
    for k in (1, 2, 3):
        b = occ.addBox(4, -2, 0, 13, 4, t)
        occ.rotate([(3, b)], 0, 0, 0, 0, 0, 1, k * math.pi / 2)
        beams.append((3, b))
    body = occ.fuse(frame, [hub] + beams)[0]
    occ.cut(body, [(3, occ.addCylinder(0, 0, 0, 0, 0, t, 2.0))])
    occ.synchronize()


PARTS = {
    "three_spoke_thin": dict(build=three_spoke_thin, kind="step", L=1.0, W=1.0, T=1.0, load_r=1.52, fixed_r=19.95,
                             gauges=lambda: _gauges(1.6, ((8.5, 0.0), (11.5, 0.0), (8.5, 120.0), (11.5, 120.0))),
                             about="A thin three-spoke disc with sharp spoke roots (STEP); a chevron pair of gauges "
                                   "on each of two spokes (no symmetry between the arms)."),
    "six_spoke_thick": dict(build=six_spoke_thick, kind="stl", L=0.8, W=0.8, T=5.0, load_r=2.52, fixed_r=21.95,
                            gauges=lambda: _gauges(6.0, ((12.5, 0.0), (12.5, 60.0), (12.5, 120.0), (12.5, 180.0))),
                            about="A thick six-spoke disc with rim fillets, as an STL of gmsh's triangulation."),
    "cross_frame": dict(build=cross_frame, kind="step", L=1.5, W=1.0, T=5.0, load_r=2.02, fixed_r=19.95,
                        gauges=lambda: _gauges(5.0, ((10.5, 0.0), (10.5, 90.0), (10.5, 180.0), (10.5, 270.0))),
                        about="A cross flexure: square hub, four beams, square frame; sharp inner corners (STEP)."),
}


def write(name: str) -> Path:
    p = PARTS[name]
    OUT.mkdir(parents=True, exist_ok=True)
    geo = OUT / f"{name}.{p['kind']}"
    write_geometry(p["build"], geo)
    return write_toml(OUT, name, p, geo.name)


def write_geometry(build, geo: Path) -> None:
    """The solid drawn by ``build(gmsh)`` written to ``geo``: a STEP as drawn, an STL as gmsh's triangulation
    (≤ 1.5 mm, 16 per turn; binary)."""
    import gmsh

    gmsh.initialize(interruptible=False)     # its default leaves SIGINT at SIG_DFL for good
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        build(gmsh)
        if geo.suffix == ".stl":
            gmsh.option.setNumber("Mesh.MeshSizeMax", 1.5)
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 16)
            gmsh.option.setNumber("Mesh.Binary", 1)
            gmsh.model.mesh.generate(2)
        gmsh.write(str(geo))
    finally:
        gmsh.finalize()


def write_toml(out: Path, name: str, p: dict, file: str, maker: str = "fem_unseen_parts.py") -> Path:
    """The design TOML of part ``name`` (its dict ``p``: about, kind, L, W, gauges(), T, load_r, fixed_r)."""
    toml = out / f"{name}.toml"
    toml.write_text(HEADER.replace("fem_unseen_parts.py", maker).format(
        about=p["about"], name=name, kind=p["kind"], file=file, L=p["L"], W=p["W"], gauges=p["gauges"](), T=p["T"],
        load_r=p["load_r"], fixed_r=p["fixed_r"]))
    return toml


def main(argv: list[str], parts: dict | None = None, write_part=None) -> int:
    for name in argv or (parts or PARTS):
        print((write_part or write)(name))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
