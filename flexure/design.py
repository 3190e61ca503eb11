"""Design files (TOML) → a ``Design`` in SI units, validated by their schema
(userio.schema.design: every field, its unit and range, documented in docs/inputs.md).

Lengths in the file are in millimetres (keys end in ``_mm``), converted to metres here.
Tables: ``[geometry]`` (kind = "spoke_disc" | "stl" | "step"), ``[material]``, ``[gauges]``, ``[loads]``,
``[bridge]``, ``[mesh]``. See designs/paper_disc.toml for every key with its meaning.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from userio.errors import InputError
from userio.files import read_toml
from flexure.gauges import Gauge
from flexure.geometry import SpokeDisc

TABLES = {"name", "description", "geometry", "material", "gauges", "loads", "bridge", "mesh"}
MAX_CAD_BYTES = 512 << 20            # an STL/STEP flexure part (a fine STL of one part is ~10–50 MB)
NEAR_INCOMPRESSIBLE_NU = 0.49         # from here linear tetrahedra lock and CG slows down
MIN_ELEMENTS_ACROSS = 2               # elements across the thinnest wall of a mesh


@dataclass
class Design:
    """Everything one analysis needs (SI units)."""

    path: Path
    name: str
    kind: str                         # "spoke_disc" | "stl" | "step"
    disc: SpokeDisc | None
    file_path: Path | None            # the STL or STEP file
    file_unit_m: float                # its length unit in metres
    material: object                  # flexure.material.Material
    gauges: list[Gauge]
    gauge_factor: float
    gauge_resistance_ohm: float
    rated_torque_Nm: float
    load_radius_max_m: float          # surface nodes with r ≤ this carry the load (hub bore)
    fixed: str                        # "rim_bolts" | "rim_outer" | "radius"
    fixed_radius_min_m: float
    sensor_path: Path | None
    size: str
    order: int
    raw: dict = field(repr=False, default_factory=dict)
    segments_per_quarter: int | None = None
    mesher: str = "gmsh"                  # "gmsh" (graded isotropic volume) | "sweep" (layered extrusion) | "tetgen"
    coupling: str = "rigid"               # torque into the bore: "rigid" shaft | "distributed" traction


def load_design(path: str | Path, overrides: dict | None = None) -> Design:
    """Read a design TOML; ``overrides`` {"spoke_width_mm": 5.0, "mesh.size": "fine", ...} apply on top."""
    from userio.files import check_input

    path = check_input(path, what="design file")    # not found, a directory or a device: say which
    return design_from_dict(read_toml(path), path, overrides)


def apply_override(raw: dict, key: str, value, where: str = "--sweep") -> dict:
    """Set ``key`` (a geometry key like ``spoke_width_mm`` or ``table.key``) in a copy of ``raw``."""
    from userio.schema.design import DISC_KEYS

    raw = copy.deepcopy(raw)
    if "." in key:
        table, k = key.split(".", 1)
    else:
        table, k = "geometry", key
        if k in ("rated_torque_Nm",):
            table = "loads"
    if table not in TABLES - {"name", "description"}:
        raise InputError(f"{where}: unknown parameter {key!r}")
    if table == "geometry" and k not in DISC_KEYS:
        raise InputError(f"{where}: unknown geometry parameter {key!r} (known: {', '.join(DISC_KEYS)})")
    raw.setdefault(table, {})[k] = value
    return raw


def design_from_dict(raw: dict, path: Path, overrides: dict | None = None) -> Design:
    """A design file validated by its schema (userio.schema.design.DesignFile), then built in SI
    units: the gauge layout placed on the disc, the CAD and sensor files located."""
    from flexure.material import Material
    from userio.files import check_input
    from userio.schema import parse
    from userio.schema.design import DesignFile

    for k, v in (overrides or {}).items():
        raw = apply_override(raw, k, v)
    f = str(path)
    d = parse(DesignFile, raw, f)
    geo, g, ld = d.geometry, d.gauges, d.loads
    disc, file_path, unit = geo.disc(), None, 1e-3
    if disc is None:
        file_path = path.parent / geo.file
        check_input(file_path, f"{f}: geometry.file", max_bytes=MAX_CAD_BYTES,
                    what=f"{geo.kind.upper()} file")
        unit = (geo.unit_mm or 1.0) * 1e-3
    L, Wd = g.grid_length_mm * 1e-3, g.grid_width_mm * 1e-3
    if (g.layout or ("shear_45" if disc is not None else "explicit")) == "shear_45":
        pos = g.position if g.position is not None else (disc.pad_position if disc.pad_width else 0.5)
        gauges = shear_45_layout(disc, L, Wd, pos, f"{f}: gauges")
    else:
        gauges = [Gauge(tuple(np.asarray(e.centre_mm) * 1e-3), tuple(e.axis), tuple(e.normal), L, Wd,
                        e.arm, e.name or f"g{e.arm}") for e in g.gauge]
    if disc is not None:
        fixed = ld.fixed or ("rim_bolts" if disc.rim_bolts else "rim_outer")
        load_r = (ld.load_radius_max_mm or disc.bore_radius * 1e3 * 1.001) * 1e-3
        fixed_r = (ld.fixed_radius_min_mm or disc.outer_radius * 1e3 * 0.999) * 1e-3
    else:
        fixed, load_r, fixed_r = "radius", ld.load_radius_max_mm * 1e-3, ld.fixed_radius_min_mm * 1e-3
    if not load_r < fixed_r:
        raise InputError(f"{f}: loads.load_radius_max_mm: must be > 0 and below fixed_radius_min_mm")
    sensor = None
    if d.bridge.sensor is not None:
        sensor = path.parent / d.bridge.sensor
        if not sensor.is_file():
            raise InputError(f"{f}: bridge.sensor: {sensor} not found")
    return Design(path, d.name if d.name is not None else path.stem, geo.kind, disc, file_path, unit,
                  Material(**d.material.values()), gauges, g.gauge_factor, g.resistance_ohm,
                  ld.rated_torque_Nm, load_r, fixed, fixed_r, sensor, d.mesh.size, d.mesh.order,
                  raw=raw, segments_per_quarter=geo.segments_per_quarter, mesher=d.mesh.mesher,
                  coupling=ld.coupling)


def shear_45_layout(disc: SpokeDisc, length_m: float, width_m: float, position: float, where: str):
    """Four ±45° gauges on the top face (z = thickness), centred on the spoke axis at ``position``.

    N divisible by 4: one gauge on each of spokes 0, N/4, N/2, 3N/4 (arms 1–4); other even N:
    a chevron pair side by side on spokes 0 (arms 1, 2) and N/2 (arms 3, 4). Angles from the
    outward radial direction, counterclockwise seen from +z: arms 1, 3 at −45°, arms 2, 4 at +45°,
    so that a positive torque on the hub (about +z, rim held) gives a positive bridge output.
    """
    N = disc.spokes
    ang = disc.spoke_angles_rad()
    rc = disc.hub_radius + position * disc.spoke_length
    half = 0.5 * (length_m + width_m) / math.sqrt(2)   # half footprint of a 45° grid
    if N % 4 == 0:
        spokes, offsets = [0, N // 4, N // 2, 3 * N // 4], [0.0] * 4
    elif N % 2 == 0:
        spokes, offsets = [0, 0, N // 2, N // 2], [-1.05 * half, 1.05 * half] * 2
    else:
        raise InputError(f"{where}.layout: 'shear_45' needs an even number of spokes; "
                         "declare [[gauges.gauge]] explicitly")
    width_here = max(disc.spoke_width, disc.pad_width)
    if 2 * half > width_here:
        raise InputError(f"{where}.grid_length_mm: a 45° grid of {length_m * 1e3:g} × {width_m * 1e3:g} mm "
                         f"does not fit on a {width_here * 1e3:g} mm spoke")
    gauges = []
    for arm, (k, off) in enumerate(zip(spokes, offsets), start=1):
        r_hat = np.array([math.cos(ang[k]), math.sin(ang[k]), 0.0])
        t_hat = np.array([-r_hat[1], r_hat[0], 0.0])
        r = rc + off
        if not (disc.hub_radius + half < r < disc.rim_inner_radius - half):
            raise InputError(f"{where}.position: the gauges do not fit on the free spoke length")
        sign = -1.0 if arm in (1, 3) else 1.0
        axis = (r_hat + sign * t_hat) / math.sqrt(2)
        gauges.append(Gauge(tuple(r * r_hat + np.array([0, 0, disc.thickness])), tuple(axis), (0.0, 0.0, 1.0),
                            length_m, width_m, arm, f"g{arm}"))
    return gauges


def thinnest_wall(design: Design) -> tuple[float, str] | None:
    """(thickness in m, what it is) of the thinnest wall of a parametric disc: the disc itself,
    a spoke, the hub and rim rings, the ligaments beside and between bolt holes (None for an
    STL/STEP part, whose walls are not declared)."""
    d = design.disc
    if d is None:
        return None
    walls = [(d.thickness, "geometry.thickness_mm"), (d.spoke_width, "geometry.spoke_width_mm"),
             (d.hub_radius - d.bore_radius, "the hub ring (hub_radius_mm − bore_radius_mm)"),
             (d.outer_radius - d.rim_inner_radius, "the rim ring (outer_radius_mm − rim_inner_radius_mm)")]
    for prefix, rin, rout in (("hub", d.bore_radius, d.hub_radius), ("rim", d.rim_inner_radius, d.outer_radius)):
        n = getattr(d, f"{prefix}_bolts")
        if n:
            rc, dia = getattr(d, f"{prefix}_bolt_circle_radius"), getattr(d, f"{prefix}_bolt_diameter")
            walls += [(rc - dia / 2 - rin, f"the {prefix} bolt holes' inner ligament"),
                      (rout - rc - dia / 2, f"the {prefix} bolt holes' outer ligament"),
                      (2 * math.pi * rc / n - dia, f"the ligament between {prefix} bolt holes")]
    return min(walls)


def curved_walls(d) -> list:
    """The spoke disc's curved faces for the mesh-cost estimate (flexure.sizing.estimate_parts):
    (design key, radius m, total wall height m, arc fraction, material outside the circle?)."""
    t = d.thickness
    n_arms = len(d.spoke_angles_rad())
    return [("geometry.bore_radius_mm", d.bore_radius, t, 1.0, True),
            ("geometry.hub_bolt_diameter_mm", d.hub_bolt_diameter / 2, t * d.hub_bolts, 1.0, True),
            ("geometry.rim_bolt_diameter_mm", d.rim_bolt_diameter / 2, t * d.rim_bolts, 1.0, True),
            ("geometry.rim_inner_radius_mm", d.rim_inner_radius, t, 1.0, True),
            ("geometry.hub_radius_mm", d.hub_radius, t, 1.0, False),
            ("geometry.outer_radius_mm", d.outer_radius, t, 1.0, False),
            ("geometry.fillet_radius_mm", d.fillet_radius, 4 * n_arms * t, 0.25, True)]


def preflight(design: Design, size: str | None = None, order: int | None = None,
              max_elements: float | None = None, levels: int = 3) -> dict:
    """Cost and soundness before any meshing, for ``levels`` mesh levels (1: the answer's; 2: a
    sweep row's h and h·√2; 3: the error estimate's h·√2, h, h/√2):

    - tetrahedra per level from the mesh size field, whose element size is bounded by the part's
      own thickness (flexure.meshing.estimate_elements); a level above ``max_elements`` is refused
      now, naming the thinnest wall that sets the size and the knob to turn — not after the
      coarser levels ran;
    - near-incompressible material: P1 from ν ≥ 0.49 locks (its numbers would be withheld) and P2
      from ν ≥ 0.49999 is beyond its measured accuracy: refused; P2 from 0.49 warned (the solver
      needs more iterations).
    Returns {"elements_estimate" (at the answer's level), "levels", "warnings"}."""
    from flexure.meshing import SIZES, size_field
    from flexure.sizing import BYTES_PER_ELEMENT, MAX_ELEMENTS, estimate_parts
    from flexure.solve import NU_LOCKING

    size = size or design.size
    order = order or design.order
    cap = max_elements or MAX_ELEMENTS
    warnings: list[str] = []
    nu = design.material.nu
    where = f"{design.path}: material.nu"
    if nu >= NU_LOCKING[order]:
        raise InputError(f"{where}: ν = {nu:g} is near-incompressible for P{order} tetrahedra (from "
                         f"{NU_LOCKING[order]:g} they lock or leave their measured accuracy: the numbers "
                         "would be withheld after a long solve)" + ("; use order 2 (P2)" if order == 1 else ""))
    if nu >= NEAR_INCOMPRESSIBLE_NU:
        warnings.append(f"material.nu = {nu:g} is near-incompressible: the solve needs more iterations "
                        "and its result carries a condition warning if it is ill-posed")
    out = {"elements_estimate": None, "levels": [], "warnings": warnings}
    if design.disc is None or size not in SIZES:
        return out
    from flexure.geometry import profile

    d = design.disc
    poly = profile(d, 3)
    V = poly.area * d.thickness
    A = 2 * poly.area + (poly.exterior.length + sum(r.length for r in poly.interiors)) * d.thickness
    centres = np.array([g.centre_m for g in design.gauges])
    extent = 0.5 * max(g.length_m + g.width_m for g in design.gauges) / math.sqrt(2) * 1.3
    gw = min(min(g.width_m, g.length_m) for g in design.gauges)
    factors = {1: (1.0,), 2: (2 ** 0.5, 1.0), 3: (2 ** 0.5, 1.0, 2 ** -0.5)}.get(levels, (1.0,))
    walls = curved_walls(d) if design.mesher == "gmsh" else ()
    for f in factors:
        field = size_field(size, d.thickness, centres, extent, gw, f)
        parts = estimate_parts(field, V, 2 * V / A, walls)
        n = float(sum(parts.values()))
        out["levels"].append({"h_factor": f, "elements_estimate": n})
        if f == 1.0:
            out["elements_estimate"] = n
        if not np.isfinite(n) or n > cap:
            lvl = "" if f == 1.0 else f" level h × {f:.3g}{' (the finest)' if f < 1 else ''}"
            top = max(parts, key=lambda k: parts[k] if np.isfinite(parts[k]) else math.inf)
            if top in ("volume", "edges"):
                wall, what = thinnest_wall(design)
                why = (f"the thinnest wall, {what} = {wall * 1e3:.3g} mm, bounds the element size (h ≤ "
                       f"{min(field.h_far, 2 * V / A) * 1e3:.3g} mm over {V * 1e9:.4g} mm³)")
                fix = "Thicken the wall, use --single-level"
            elif top == "gauges":
                why = (f"the gauges (gauges.grid_width_mm / grid_length_mm: {field.h_gauge * 1e3:.3g} mm elements "
                       f"at each of {len(centres)}, graded out to {field.h_far * 1e3:.3g} mm)")
                fix = "Use larger gauge grids, --single-level"
            else:
                R = next(r for k, r, *_ in walls if k == top)
                why = (f"{top}'s curved walls ({100 * parts[top] / n:.0f} %: {2 * math.pi * R / field.curvature_elements * 1e3:.3g} mm "
                       f"elements, 2πR / {field.curvature_elements:.3g} per turn, over walls geometry.thickness_mm = "
                       f"{d.thickness * 1e3:.4g} mm tall)")
                fix = "Check geometry.thickness_mm and that radius, use --single-level"
            raise InputError(
                f"{design.path}: the mesh{lvl} would have ~{n:.3g} tetrahedra (~{n * BYTES_PER_ELEMENT / 1e9:.3g} GB "
                f"for P2), above --max-elements {cap:.3g}: {why}; refused before meshing. {fix}"
                + (" or --size coarse" if size != "coarse" else "") + ", or raise --max-elements")
    return out
