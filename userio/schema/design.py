"""A flexure design (``designs/paper_disc.toml``): geometry, material, gauges, loads, bridge, mesh.

Lengths in the file are in millimetres (keys end in ``_mm``); flexure.design converts them to SI.
A parametric spoke disc's keys default to flexure.geometry.SpokeDisc's values; an STL or STEP
part (``geometry.kind``) names its file instead.
"""

from __future__ import annotations

import math
from typing import Literal, Optional

from pydantic import model_validator

from userio.errors import InputError
from userio.schema.base import Field, Model, Range, fail, integer, num, vector

MATERIAL_PRESETS = {"6061-T6": dict(E_Pa=68.9e9, nu=0.33, yield_Pa=276e6, name="aluminium 6061-T6"),
                    "7075-T6": dict(E_Pa=71.7e9, nu=0.33, yield_Pa=503e6, name="aluminium 7075-T6"),
                    "17-4PH-H900": dict(E_Pa=196e9, nu=0.272, yield_Pa=1170e6, name="steel 17-4PH H900")}
SIZES = ("coarse", "medium", "fine")
from flexure.meshing import MESHERS  # noqa: E402  (the mesh generators flexure offers)

LENGTH_MM = Range(0.01, 5000.0, "mm", low="below 10 µm: m or µm typed as mm?",
                  high="a flexure over 5 m: µm typed as mm?")
FEATURE_MM = Range(0.01, 5000.0, "mm", zero_ok=True, low="below 10 µm: m or µm typed as mm?",
                   high="a flexure over 5 m: µm typed as mm?")      # 0: an optional feature left out
HOLES = Range(0, 360, "holes")


def _mm(description: str):
    """A spoke-disc key, its default flexure.geometry.SpokeDisc's (in the file's unit)."""
    return Field(None, description=description)


def _disc_defaults(cls):
    """Geometry's spoke-disc keys default to SpokeDisc's values, in mm (documented, applied)."""
    import dataclasses

    from flexure.geometry import SpokeDisc

    si = {f.name: f.default for f in dataclasses.fields(SpokeDisc)}
    for key in DISC_KEYS:
        name = key.removesuffix("_mm")
        value = si[name] * 1e3 if key.endswith("_mm") else si[name]
        cls.model_fields[key].default = round(value, 9) if isinstance(value, float) else value
    cls.model_rebuild(force=True)
    return cls


class Geometry(Model):
    """``[geometry]``: a parametric hub–spokes–rim disc, or an STL/STEP part."""

    kind: Literal["spoke_disc", "stl", "step"] = Field("spoke_disc", description="the part")
    outer_radius_mm: Optional[num(FEATURE_MM)] = _mm("rim outside radius")
    rim_inner_radius_mm: Optional[num(FEATURE_MM)] = _mm("spokes end here")
    hub_radius_mm: Optional[num(FEATURE_MM)] = _mm("spokes start here")
    bore_radius_mm: Optional[num(FEATURE_MM)] = _mm("the shaft bore: the torque enters through its wall")
    thickness_mm: Optional[num(FEATURE_MM)] = _mm("disc thickness (z); gauges on the top face")
    spokes: Optional[integer(Range(2, 360, "spokes"))] = _mm("number of spokes")
    spoke_width_mm: Optional[num(FEATURE_MM)] = _mm("spoke width")
    fillet_radius_mm: Optional[num(FEATURE_MM)] = _mm("spoke-root fillets (0: none)")
    hub_bolts: Optional[integer(HOLES)] = _mm("clearance holes on the hub (0: none)")
    hub_bolt_circle_radius_mm: Optional[num(FEATURE_MM)] = _mm("their circle")
    hub_bolt_diameter_mm: Optional[num(FEATURE_MM)] = _mm("their diameter")
    rim_bolts: Optional[integer(HOLES)] = _mm("clearance holes on the rim (0: none)")
    rim_bolt_circle_radius_mm: Optional[num(FEATURE_MM)] = _mm("their circle")
    rim_bolt_diameter_mm: Optional[num(FEATURE_MM)] = _mm("their diameter")
    pad_width_mm: Optional[num(FEATURE_MM)] = _mm("gauge pad: local spoke widening (0: none)")
    pad_length_mm: Optional[num(FEATURE_MM)] = _mm("gauge pad length along the spoke")
    pad_position: Optional[num()] = _mm("gauge pad centre along the free spoke length, (0, 1)")
    phase_deg: Optional[num(Range(-360.0, 360.0, "deg"))] = _mm("angle of spoke 0 from +x")
    segments_per_quarter: Optional[integer(Range(1, 1000, "segments"))] = Field(
        None, description="arc segments per quarter circle of the outline (default: by mesh size)")
    file: Optional[str] = Field(None, description="stl, step: the part's file, relative to this file")
    unit_mm: Optional[num(gt=0)] = Field(None, description="stl: its length unit in mm (default 1; "
                                         "a STEP file declares its own)")

    @property
    def disc_keys(self) -> list[str]:
        """The spoke-disc keys the file gives."""
        return [k for k in DISC_KEYS if k in self.model_fields_set]

    def disc(self):
        """The flexure.geometry.SpokeDisc (SI units) of a spoke disc; None for a CAD part."""
        if self.kind != "spoke_disc":
            return None
        from flexure.geometry import SpokeDisc

        return SpokeDisc(**{k.removesuffix("_mm"): getattr(self, k) * (1e-3 if k.endswith("_mm") else 1)
                            for k in self.disc_keys})      # the rest: SpokeDisc's own SI defaults

    @model_validator(mode="after")
    def _consistent(self):
        if self.kind == "spoke_disc":
            for k in ("file", "unit_mm"):
                if getattr(self, k) is not None:
                    raise fail(k, "only for kind = 'stl' or 'step'")
            try:
                self.disc().check(where="geometry")
            except InputError as exc:                    # SpokeDisc names → the file's keys
                name, why = str(exc).removeprefix("geometry.").split(": ", 1)
                raise fail(name + ("_mm" if name + "_mm" in DISC_KEYS else ""), why) from None
            return self
        if self.disc_keys or self.segments_per_quarter is not None:
            key = (self.disc_keys or ["segments_per_quarter"])[0]
            raise fail(key, f"only for kind = 'spoke_disc' (a {self.kind.upper()} part is its file)")
        if self.file is None:
            raise fail("file", "missing field")
        if self.kind == "step" and self.unit_mm is not None:
            raise fail("unit_mm", "a STEP file declares its own length unit (OpenCASCADE reads it "
                       "and converts to mm); unit_mm is for STL files, which have none")
        return self


DISC_KEYS = [k for k in Geometry.model_fields
             if k not in ("kind", "segments_per_quarter", "file", "unit_mm")]
_disc_defaults(Geometry)


class Material(Model):
    """``[material]``: a preset, any of its values overridden."""

    preset: Literal[tuple(MATERIAL_PRESETS)] = Field(
        "6061-T6", description="6061-T6 (E 68.9 GPa, ν 0.33, σ_y 276 MPa), 7075-T6 (71.7, 0.33, "
        "503), 17-4PH-H900 (196, 0.272, 1170)")
    E_GPa: Optional[num(Range(0.01, 1500.0, "GPa", low="MPa or kPa? (E is in GPa: aluminium 68.9, "
                              "steel 200)", high="E given in Pa or MPa? the key is E_GPa (aluminium "
                              "68.9, steel 200)"), gt=0)] = Field(None, description="Young's modulus")
    nu: Optional[num(Range(-0.99, 0.49999, "", high="ν ≥ 0.5 is not an elastic solid"),
                     gt=-1.0, lt=0.5)] = Field(None, description="Poisson's ratio")
    yield_MPa: Optional[num(Range(1.0, 1e5, "MPa", high="yield given in Pa? the key is yield_MPa"),
                            gt=0)] = Field(None, description="yield strength (the safety factor)")
    name: Optional[str] = Field(None, description="label")

    def values(self) -> dict:
        """flexure.material.Material's keyword arguments (SI)."""
        base = dict(MATERIAL_PRESETS[self.preset])
        for key, si, scale in (("E_GPa", "E_Pa", 1e9), ("nu", "nu", 1.0),
                               ("yield_MPa", "yield_Pa", 1e6), ("name", "name", None)):
            v = getattr(self, key)
            if v is not None:
                base[si] = v if scale is None else v * scale
        return base


class GaugeEntry(Model):
    """``[[gauges.gauge]]``: one gauge of an explicit layout (four, one per bridge arm)."""

    centre_mm: vector(3) = Field(description="grid centre on the part's surface")
    axis: vector(3) = Field(description="grid direction (the strain it reads)")
    normal: vector(3) = Field((0.0, 0.0, 1.0), description="outward surface normal")
    arm: Literal[1, 2, 3, 4] = Field(description="bridge arm")
    name: Optional[str] = Field(None, description="label (default g<arm>)")

    @model_validator(mode="after")
    def _axis(self):
        a, n = self.axis, self.normal
        cross = (a[1] * n[2] - a[2] * n[1], a[2] * n[0] - a[0] * n[2], a[0] * n[1] - a[1] * n[0])
        if math.hypot(*n) == 0 or math.hypot(*cross) < 1e-6 * math.hypot(*a):
            raise fail("axis", "must be non-zero and not parallel to the normal")
        return self


class Gauges(Model):
    """``[gauges]``: the four gauges of the full bridge."""

    layout: Optional[Literal["shear_45", "explicit"]] = Field(
        None, description="shear_45: ±45° gauges on the spoke centre lines (a spoke disc; the "
        "default there); explicit: four [[gauges.gauge]] (the default for STL/STEP)")
    grid_length_mm: num(LENGTH_MM, gt=0) = Field(3.0, description="grid length")
    grid_width_mm: num(LENGTH_MM, gt=0) = Field(2.2, description="grid width")
    position: Optional[num(gt=0, lt=1)] = Field(
        None, description="shear_45: along the free spoke length, hub (0) to rim (1) (default: the "
        "pad's position, else 0.5)")
    gauge_factor: num(Range(0.1, 1000.0, ""), gt=0) = Field(2.0, description="GF")
    resistance_ohm: num(Range(1.0, 1e7, "Ω"), gt=0) = Field(1000.0, description="gauge resistance")
    gauge: list[GaugeEntry] = Field([], description="explicit: the four gauges")


class Loads(Model):
    """``[loads]``: the rated torque and how the part is held."""

    rated_torque_Nm: num(Range(1e-6, 1e6, "N·m", lo_open=True, high="N·mm typed as N·m?"),
                         gt=0) = Field(2.0, description="rated torque (stress, safety factor)")
    fixed: Optional[Literal["rim_bolts", "rim_outer", "radius"]] = Field(
        None, description="held at: the rim's bolt-hole walls (default with rim bolts), the rim's "
        "outside (default without), or every surface node beyond fixed_radius_min_mm (STL/STEP)")
    load_radius_max_mm: Optional[num(gt=0)] = Field(
        None, description="surface nodes with r ≤ this carry the torque (default: the bore wall; "
        "required for STL/STEP)")
    fixed_radius_min_mm: Optional[num(gt=0)] = Field(
        None, description="surface nodes with r ≥ this are held (default: the rim's outside; "
        "required for STL/STEP)")
    coupling: Literal["rigid", "distributed"] = Field(
        "rigid", description="torque into the bore by a rigid shaft, or as the statically "
        "equivalent traction (a compliant hub)")


class BridgeRef(Model):
    """``[bridge]``: the sensor electronics of the noise budget."""

    sensor: Optional[str] = Field(None, description="a sensor file (userio.schema.sensor), "
                                  "relative to this file")


class Mesh(Model):
    """``[mesh]``: the finite-element mesh."""

    size: Literal[SIZES] = Field("coarse", description="element size near the gauges")
    order: Literal[1, 2] = Field(2, description="1: 4-node, 2: 10-node tetrahedra")
    mesher: Literal[MESHERS] = Field(
        "gmsh", description="gmsh: graded isotropic volume; sweep: layered extrusion (spoke disc "
        "only); tetgen")


class DesignFile(Model):
    """A torque flexure to analyse (``torquebench flexure DESIGN.toml``, a scene's ``[flexure]``)."""

    name: Optional[str] = Field(None, description="label (default: the file's stem)")
    description: Optional[str] = Field(None, description="free text")
    geometry: Geometry = Field(Geometry(), description="the part")
    material: Material = Field(Material(), description="its material")
    gauges: Gauges = Field(Gauges(), description="the gauges")
    loads: Loads = Field(Loads(), description="rated torque and supports")
    bridge: BridgeRef = Field(BridgeRef(), description="the sensor electronics")
    mesh: Mesh = Field(Mesh(), description="the mesh")

    @model_validator(mode="after")
    def _consistent(self):
        disc = self.geometry.kind == "spoke_disc"
        g, ld = self.gauges, self.loads
        layout = g.layout or ("shear_45" if disc else "explicit")
        if layout == "shear_45" and not disc:
            raise fail("gauges.layout", "'shear_45' needs geometry.kind = 'spoke_disc'; declare "
                       "[[gauges.gauge]] for an STL")
        if layout == "explicit":
            if len(g.gauge) != 4:
                raise fail("gauges.gauge", "need exactly four [[gauges.gauge]] entries (one per "
                           "bridge arm)")
            if sorted(e.arm for e in g.gauge) != [1, 2, 3, 4]:
                raise fail("gauges.gauge", "arms must be 1, 2, 3 and 4, each once")
        if ld.fixed == "rim_bolts" and not (disc and self.geometry.disc().rim_bolts):
            raise fail("loads.fixed", "'rim_bolts' needs geometry.rim_bolts > 0")
        if not disc:
            for k in ("load_radius_max_mm", "fixed_radius_min_mm"):
                if getattr(ld, k) is None:
                    raise fail(f"loads.{k}", "missing field (required for an STL/STEP part)")
        if not disc and self.mesh.mesher == "sweep":
            raise fail("mesh.mesher", f"'sweep' needs an extruded profile (geometry.kind = "
                       f"'spoke_disc'); use 'gmsh' or 'tetgen' for a {self.geometry.kind.upper()} solid")
        return self
