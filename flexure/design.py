"""Design files (TOML) → a validated ``Design``; every error names the file and the field.

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

from flexure.errors import InputError
from userio.fields import Range
from userio.files import read_toml
from flexure.gauges import Gauge
from flexure.geometry import SpokeDisc
from flexure.meshing import MESHERS

DISC_KEYS = {  # TOML key → (SpokeDisc field, scale to SI)
    "outer_radius_mm": ("outer_radius", 1e-3), "rim_inner_radius_mm": ("rim_inner_radius", 1e-3),
    "hub_radius_mm": ("hub_radius", 1e-3), "bore_radius_mm": ("bore_radius", 1e-3),
    "thickness_mm": ("thickness", 1e-3), "spokes": ("spokes", None),
    "spoke_width_mm": ("spoke_width", 1e-3), "fillet_radius_mm": ("fillet_radius", 1e-3),
    "hub_bolts": ("hub_bolts", None), "hub_bolt_circle_radius_mm": ("hub_bolt_circle_radius", 1e-3),
    "hub_bolt_diameter_mm": ("hub_bolt_diameter", 1e-3), "rim_bolts": ("rim_bolts", None),
    "rim_bolt_circle_radius_mm": ("rim_bolt_circle_radius", 1e-3),
    "rim_bolt_diameter_mm": ("rim_bolt_diameter", 1e-3), "pad_width_mm": ("pad_width", 1e-3),
    "pad_length_mm": ("pad_length", 1e-3), "pad_position": ("pad_position", None),
    "phase_deg": ("phase_deg", None),
}
MATERIAL_PRESETS = {"6061-T6": dict(E_Pa=68.9e9, nu=0.33, yield_Pa=276e6, name="aluminium 6061-T6"),
                    "7075-T6": dict(E_Pa=71.7e9, nu=0.33, yield_Pa=503e6, name="aluminium 7075-T6"),
                    "17-4PH-H900": dict(E_Pa=196e9, nu=0.272, yield_Pa=1170e6, name="steel 17-4PH H900")}
SIZES = ("coarse", "medium", "fine")
TABLES = {"name", "description", "geometry", "material", "gauges", "loads", "bridge", "mesh"}

# physical ranges of a design's fields, in the file's units (userio.fields.Range)
LENGTH_MM = Range(0.01, 5000.0, "mm", low="below 10 µm: m or µm typed as mm?",
                  high="a flexure over 5 m: µm typed as mm?")
FIELD_RANGES = {
    "geometry.spokes": Range(2, 360, "spokes"), "geometry.hub_bolts": Range(0, 360, "holes"),
    "geometry.rim_bolts": Range(0, 360, "holes"), "geometry.phase_deg": Range(-360.0, 360.0, "deg"),
    "material.E_GPa": Range(0.01, 1500.0, "GPa", low="MPa or kPa? (E is in GPa: aluminium 68.9, "
                            "steel 200)", high="E given in Pa or MPa? the key is E_GPa (aluminium "
                            "68.9, steel 200)"),
    "material.yield_MPa": Range(1.0, 1e5, "MPa", high="yield given in Pa? the key is yield_MPa"),
    "material.nu": Range(-0.99, 0.49999, "", high="ν ≥ 0.5 is not an elastic solid"),
    "gauges.gauge_factor": Range(0.1, 1000.0, ""), "gauges.resistance_ohm": Range(1.0, 1e7, "Ω"),
    "loads.rated_torque_Nm": Range(1e-6, 1e6, "N·m", lo_open=True, high="N·mm typed as N·m?"),
}
MAX_CAD_BYTES = 512 << 20            # an STL/STEP flexure part (a fine STL of one part is ~10–50 MB)
NEAR_INCOMPRESSIBLE_NU = 0.49         # from here linear tetrahedra lock and CG slows down
MIN_ELEMENTS_ACROSS = 2               # elements across the thinnest wall of a mesh


def _field_range(key: str, value, where: str):
    rng = FIELD_RANGES.get(key) or (LENGTH_MM if key.endswith("_mm") else None)
    if rng is not None:
        why = rng.problem(float(value))
        if why:
            raise InputError(f"{where}: {key}: {why}")
    return value


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


def _get(table: dict, key: str, where: str, kind=float, default=None, required=False):
    if key not in table:
        if required:
            raise InputError(f"{where}.{key}: missing")
        return default
    v = table[key]
    if kind is float:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{where}.{key}: must be a number, got {v!r}")
        return float(v)
    if kind is int:
        if isinstance(v, bool) or not isinstance(v, int) and not (isinstance(v, float) and v.is_integer()):
            raise InputError(f"{where}.{key}: must be an integer, got {v!r}")
        return int(v)
    if kind is str:
        if not isinstance(v, str):
            raise InputError(f"{where}.{key}: must be a string, got {v!r}")
        return v
    if kind is bool:
        if not isinstance(v, bool):
            raise InputError(f"{where}.{key}: must be true or false, got {v!r}")
        return v
    if kind == "vec3":
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                            for x in v)):
            raise InputError(f"{where}.{key}: must be a list of 3 numbers, got {v!r}")
        return np.asarray(v, float)
    raise AssertionError(kind)


def _unknown(table: dict, allowed, where: str):
    extra = sorted(set(table) - set(allowed))
    if extra:
        raise InputError(f"{where}.{extra[0]}: unknown key (known: {', '.join(sorted(allowed))})")


def load_design(path: str | Path, overrides: dict | None = None) -> Design:
    """Read a design TOML; ``overrides`` {"spoke_width_mm": 5.0, "mesh.size": "fine", ...} apply on top."""
    from userio.files import check_input

    path = check_input(path, what="design file")    # not found, a directory or a device: say which
    return design_from_dict(read_toml(path), path, overrides)


def apply_override(raw: dict, key: str, value, where: str = "--sweep") -> dict:
    """Set ``key`` (a geometry key like ``spoke_width_mm`` or ``table.key``) in a copy of ``raw``."""
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
    for k, v in (overrides or {}).items():
        raw = apply_override(raw, k, v)
    f = str(path)
    _unknown(raw, TABLES, f)
    for t in TABLES - {"name", "description"}:
        if t in raw and not isinstance(raw[t], dict):
            raise InputError(f"{f}: [{t}] must be a table")
    name = raw.get("name", path.stem)
    geo = raw.get("geometry", {})
    w = f"{f}: geometry"
    kind = _get(geo, "kind", w, str, "spoke_disc")
    disc, file_path, unit = None, None, 1e-3
    if kind == "spoke_disc":
        _unknown(geo, set(DISC_KEYS) | {"kind", "segments_per_quarter"}, w)
        kw = {}
        for key, (fld, scale) in DISC_KEYS.items():
            if key in geo:
                if scale is None and fld in ("spokes", "hub_bolts", "rim_bolts"):
                    kw[fld] = _field_range(f"geometry.{key}", _get(geo, key, w, int), f)
                else:
                    value = _get(geo, key, w)
                    if key.endswith("_mm") and value != 0:       # 0: an optional feature left out
                        _field_range(f"geometry.{key}", value, f)
                    elif key in FIELD_RANGES or f"geometry.{key}" in FIELD_RANGES:
                        _field_range(f"geometry.{key}", value, f)
                    kw[fld] = value * (scale or 1.0)
        disc = SpokeDisc(**kw)
        try:
            disc.check(where=w)
        except InputError as exc:     # map SpokeDisc field names back to TOML keys
            msg = str(exc)
            for key, (fld, _) in sorted(DISC_KEYS.items(), key=lambda kv: -len(kv[1][0])):
                msg = msg.replace(f"geometry.{fld}:", f"geometry.{key}:")
            raise InputError(msg) from None
    elif kind in ("stl", "step"):
        _unknown(geo, {"kind", "file", "unit_mm"}, w)
        file_path = (path.parent / _get(geo, "file", w, str, required=True))
        from userio.files import check_input
        check_input(file_path, f"{w}.file", max_bytes=MAX_CAD_BYTES, what=f"{kind.upper()} file")
        if kind == "step" and "unit_mm" in geo:
            raise InputError(f"{w}.unit_mm: a STEP file declares its own length unit (OpenCASCADE reads it "
                             "and converts to mm); unit_mm is for STL files, which have none")
        unit = _get(geo, "unit_mm", w, float, 1.0) * 1e-3
        if not unit > 0:
            raise InputError(f"{w}.unit_mm: must be > 0")
    else:
        raise InputError(f"{w}.kind: must be 'spoke_disc', 'stl' or 'step', got {kind!r}")

    # material
    mat = raw.get("material", {})
    w = f"{f}: material"
    _unknown(mat, {"preset", "E_GPa", "nu", "yield_MPa", "name"}, w)
    preset = _get(mat, "preset", w, str, "6061-T6")
    if preset not in MATERIAL_PRESETS:
        raise InputError(f"{w}.preset: unknown {preset!r} (known: {', '.join(MATERIAL_PRESETS)})")
    from flexure.material import Material
    base = dict(MATERIAL_PRESETS[preset])
    if "E_GPa" in mat:
        base["E_Pa"] = _field_range("material.E_GPa", _get(mat, "E_GPa", w), f) * 1e9
    if "nu" in mat:
        base["nu"] = _get(mat, "nu", w)
        if -1 < base["nu"] < 0.5:
            _field_range("material.nu", base["nu"], f)
    if "yield_MPa" in mat:
        base["yield_Pa"] = _field_range("material.yield_MPa", _get(mat, "yield_MPa", w), f) * 1e6
    if "name" in mat:
        base["name"] = _get(mat, "name", w, str)
    if not base["E_Pa"] > 0:
        raise InputError(f"{w}.E_GPa: must be > 0")
    if not -1 < base["nu"] < 0.5:
        raise InputError(f"{w}.nu: must lie in (-1, 0.5)")
    if not base["yield_Pa"] > 0:
        raise InputError(f"{w}.yield_MPa: must be > 0")
    material = Material(**base)

    # gauges
    gt = raw.get("gauges", {})
    w = f"{f}: gauges"
    _unknown(gt, {"layout", "grid_length_mm", "grid_width_mm", "position", "gauge_factor",
                  "resistance_ohm", "gauge"}, w)
    L = _get(gt, "grid_length_mm", w, float, 3.0) * 1e-3
    Wd = _get(gt, "grid_width_mm", w, float, 2.2) * 1e-3
    if L <= 0:
        raise InputError(f"{w}.grid_length_mm: must be > 0")
    if Wd <= 0:
        raise InputError(f"{w}.grid_width_mm: must be > 0")
    gf = _get(gt, "gauge_factor", w, float, 2.0)
    if gf <= 0:
        raise InputError(f"{w}.gauge_factor: must be > 0")
    _field_range("gauges.gauge_factor", gf, f)
    r_ohm = _get(gt, "resistance_ohm", w, float, 1000.0)
    if r_ohm <= 0:
        raise InputError(f"{w}.resistance_ohm: must be > 0")
    _field_range("gauges.resistance_ohm", r_ohm, f)
    for key, v in (("grid_length_mm", L * 1e3), ("grid_width_mm", Wd * 1e3)):
        _field_range(f"gauges.{key}", v, f)
    layout = _get(gt, "layout", w, str, "shear_45" if kind == "spoke_disc" else "explicit")
    if layout == "shear_45":
        if disc is None:
            raise InputError(f"{w}.layout: 'shear_45' needs geometry.kind = 'spoke_disc'; "
                             "declare [[gauges.gauge]] for an STL")
        pos = _get(gt, "position", w, float, disc.pad_position if disc.pad_width else 0.5)
        if not 0 < pos < 1:
            raise InputError(f"{w}.position: must lie in (0, 1) along the free spoke length")
        gauges = shear_45_layout(disc, L, Wd, pos, w)
    elif layout == "explicit":
        items = gt.get("gauge", [])
        if not isinstance(items, list) or len(items) != 4:
            raise InputError(f"{w}.gauge: need exactly four [[gauges.gauge]] entries (one per bridge arm)")
        gauges = []
        for i, item in enumerate(items):
            wi = f"{w}.gauge[{i}]"
            _unknown(item, {"centre_mm", "axis", "normal", "arm", "name"}, wi)
            c = _get(item, "centre_mm", wi, "vec3", required=True) * 1e-3
            a = _get(item, "axis", wi, "vec3", required=True)
            n = _get(item, "normal", wi, "vec3", np.array([0.0, 0.0, 1.0]))
            arm = _get(item, "arm", wi, int, required=True)
            if arm not in (1, 2, 3, 4):
                raise InputError(f"{wi}.arm: must be 1, 2, 3 or 4")
            if np.linalg.norm(n) == 0 or np.linalg.norm(np.cross(a, n)) < 1e-6 * np.linalg.norm(a):
                raise InputError(f"{wi}.axis: must be non-zero and not parallel to the normal")
            gauges.append(Gauge(tuple(c), tuple(a), tuple(n), L, Wd, arm, item.get("name", f"g{arm}")))
        if sorted(g.arm for g in gauges) != [1, 2, 3, 4]:
            raise InputError(f"{w}.gauge: arms must be 1, 2, 3 and 4, each once")
    else:
        raise InputError(f"{w}.layout: must be 'shear_45' or 'explicit', got {layout!r}")

    # loads
    ld = raw.get("loads", {})
    w = f"{f}: loads"
    _unknown(ld, {"rated_torque_Nm", "fixed", "load_radius_max_mm", "fixed_radius_min_mm", "coupling"}, w)
    coupling = _get(ld, "coupling", w, str, "rigid")
    if coupling not in ("rigid", "distributed"):
        raise InputError(f"{w}.coupling: must be 'rigid' or 'distributed', got {coupling!r}")
    rated = _get(ld, "rated_torque_Nm", w, float, 2.0)
    if rated <= 0:
        raise InputError(f"{w}.rated_torque_Nm: must be > 0")
    _field_range("loads.rated_torque_Nm", rated, f)
    fixed = _get(ld, "fixed", w, str, ("rim_bolts" if disc is not None and disc.rim_bolts else
                                        "rim_outer" if disc is not None else "radius"))
    if fixed not in ("rim_bolts", "rim_outer", "radius"):
        raise InputError(f"{w}.fixed: must be 'rim_bolts', 'rim_outer' or 'radius', got {fixed!r}")
    if fixed == "rim_bolts" and (disc is None or not disc.rim_bolts):
        raise InputError(f"{w}.fixed: 'rim_bolts' needs geometry.rim_bolts > 0")
    if disc is not None:
        load_r = _get(ld, "load_radius_max_mm", w, float, disc.bore_radius * 1e3 * 1.001) * 1e-3
        fixed_r = _get(ld, "fixed_radius_min_mm", w, float, disc.outer_radius * 1e3 * 0.999) * 1e-3
    else:
        load_r = _get(ld, "load_radius_max_mm", w, float, required=True) * 1e-3
        fixed_r = _get(ld, "fixed_radius_min_mm", w, float, required=True) * 1e-3
        fixed = "radius"
    if not 0 < load_r < fixed_r:
        raise InputError(f"{w}.load_radius_max_mm: must be > 0 and below fixed_radius_min_mm")

    # bridge
    br = raw.get("bridge", {})
    w = f"{f}: bridge"
    _unknown(br, {"sensor"}, w)
    sensor = None
    if "sensor" in br:
        sensor = path.parent / _get(br, "sensor", w, str)
        if not sensor.is_file():
            raise InputError(f"{w}.sensor: {sensor} not found")

    # mesh
    me = raw.get("mesh", {})
    w = f"{f}: mesh"
    _unknown(me, {"size", "order", "mesher"}, w)
    size = _get(me, "size", w, str, "coarse")
    if size not in SIZES:
        raise InputError(f"{w}.size: must be one of {', '.join(SIZES)}, got {size!r}")
    order = _get(me, "order", w, int, 2)
    if order not in (1, 2):
        raise InputError(f"{w}.order: must be 1 or 2, got {order}")
    mesher = _get(me, "mesher", w, str, "gmsh")
    if mesher not in MESHERS:
        raise InputError(f"{w}.mesher: must be one of {', '.join(MESHERS)}, got {mesher!r}")
    if kind != "spoke_disc" and mesher == "sweep":
        if "mesher" in me:
            raise InputError(f"{w}.mesher: 'sweep' needs an extruded profile (geometry.kind = "
                             f"'spoke_disc'); use 'gmsh' or 'tetgen' for a {kind.upper()} solid")
        mesher = "gmsh"                        # an STL or STEP solid: graded volume mesh by gmsh
    return Design(path, str(name), kind, disc, file_path, unit, material, gauges, gf, r_ohm, rated,
                  load_r, fixed, fixed_r, sensor, size, order, raw=raw,
                  segments_per_quarter=geo.get("segments_per_quarter"), mesher=mesher, coupling=coupling)


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
    from flexure.meshing import MAX_ELEMENTS, SIZES, estimate_elements, size_field
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
    for f in factors:
        field = size_field(size, d.thickness, centres, extent, gw, f)
        n = estimate_elements(field, V, 2 * V / A)
        out["levels"].append({"h_factor": f, "elements_estimate": n})
        if f == 1.0:
            out["elements_estimate"] = n
        if not np.isfinite(n) or n > cap:
            wall, what = thinnest_wall(design)
            lvl = "" if f == 1.0 else f" level h × {f:.3g}{' (the finest)' if f < 1 else ''}"
            raise InputError(
                f"{design.path}: the mesh{lvl} would have ~{n:.3g} tetrahedra, above --max-elements "
                f"{cap:.3g}: the thinnest wall, {what} = {wall * 1e3:.3g} mm, bounds the element size "
                f"(h ≤ {min(field.h_far, 2 * V / A) * 1e3:.3g} mm over {V * 1e9:.4g} mm³); refused before "
                "meshing. Thicken the wall, use --single-level"
                + (" or --size coarse" if size != "coarse" else "") + ", or raise --max-elements")
    return out
