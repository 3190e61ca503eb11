"""What a scene gives for the sensor chain and asks for: [flexure], [sensor], [calibration],
[source] and [outputs] (paths resolved from the scene file's folder), validated field by field."""

from __future__ import annotations

from pathlib import Path

from torquebench.io import REPO_ROOT
from userio.fields import Fields as _Fields
from torquebench.scene_types import ChainSpec


SESSION_KEYS = {"masses_g", "lever_arm_m", "repeats", "n_avg", "seed"}
MAX_SESSION_SAMPLES = 2e7            # ADC codes a simulated calibration session draws (160 MB)


def _file(f: _Fields, table: dict, key: str, where: str, shipped: str) -> Path:
    """A file named in the scene: beside the scene, else in the repository's ``shipped`` folder."""
    name = f.string(table, key, where)
    for cand in (f.path.parent / name, REPO_ROOT / shipped / name, Path(name)):
        if cand.is_file():
            return cand
    raise f.err(f"{where}.{key}", f"file {name!r} not found beside the scene or in {shipped}/")


def _chain_spec(f: _Fields, data: dict, kind: str) -> ChainSpec:
    fx = f.table(data, "flexure")
    f.known(fx, {"design", "strain_per_Nm"}, "flexure")
    if "design" in fx and "strain_per_Nm" in fx:
        raise f.err("flexure.strain_per_Nm", "give either a flexure design or a strain_per_Nm, not both")
    design = _file(f, fx, "design", "flexure", "scenes") if "design" in fx else None
    spn = f.number(fx, "strain_per_Nm", "flexure", positive=True) if "strain_per_Nm" in fx else None
    se = f.table(data, "sensor")
    f.known(se, {"file", "true_gain_factor"}, "sensor")
    sensor_file = _file(f, se, "file", "sensor", "scenes") if "file" in se else None
    gain = f.number(se, "true_gain_factor", "sensor", 1.0, positive=True)
    ca = f.table(data, "calibration")
    f.known(ca, {"file"} | SESSION_KEYS, "calibration")
    cal_file, session = None, None
    if "file" in ca:
        extra = sorted(set(ca) & SESSION_KEYS)
        if extra:
            raise f.err(f"calibration.{extra[0]}", "give either a calibration file or a simulated "
                        "session, not both")
        cal_file = _file(f, ca, "file", "calibration", "calibration/data")
    elif ca:
        masses = f.vector(ca, "masses_g", "calibration", positive=True,
                          default=[10, 20, 50, 100, 200, 300, 500, 700, 850, 1000])
        if masses.size < 3:
            raise f.err("calibration.masses_g", f"need at least 3 load levels, got {masses.size}")
        from calibration.session import LEVER_ARM_RANGE_M, MASS_RANGE_G

        for m_g in masses:
            if MASS_RANGE_G.problem(float(m_g)):
                raise f.err("calibration.masses_g", MASS_RANGE_G.problem(float(m_g)))
        session = {"masses_g": masses.tolist(),
                   "lever_arm_m": f.number(ca, "lever_arm_m", "calibration", 0.205, positive=True),
                   "repeats": f.integer(ca, "repeats", "calibration", 3, lo=1, hi=10_000),
                   "n_avg": f.integer(ca, "n_avg", "calibration", 256, lo=1, hi=10_000_000),
                   "seed": f.integer(ca, "seed", "calibration", 0, lo=0)}
        if LEVER_ARM_RANGE_M.problem(session["lever_arm_m"]):
            raise f.err("calibration.lever_arm_m", LEVER_ARM_RANGE_M.problem(session["lever_arm_m"]))
        n = len(masses) * session["repeats"] * session["n_avg"]
        if n > MAX_SESSION_SAMPLES:          # the simulated session holds every ADC code at once
            raise f.err("calibration.n_avg", f"{len(masses)} masses × {session['repeats']} repeats × "
                        f"n_avg {session['n_avg']} = {n:.3g} ADC samples ({8 * n / 2**30:.3g} GiB) to "
                        f"simulate, above {MAX_SESSION_SAMPLES:.0e}; lower n_avg or repeats")
    so = f.table(data, "source")
    f.known(so, {"log", "counts_columns", "reading_unit"}, "source")
    log_file = _file(f, so, "log", "source", "samples") if "log" in so else None
    cols = so.get("counts_columns", [])
    if not isinstance(cols, list) or not all(isinstance(c, str) for c in cols):
        raise f.err("source.counts_columns", f"expected a list of column names, got {cols!r}")
    if cols and log_file is None:
        raise f.err("source.counts_columns", "counts columns need a recorded log (source.log)")
    if cols and cal_file is None and session is None:
        raise f.err("source.counts_columns", "raw ADC counts need a [calibration] to become torques")
    unit = f.choice(so, "reading_unit", "source", ("counts", "mV"), "counts")
    if "reading_unit" in so and not cols:
        raise f.err("source.reading_unit", "says what source.counts_columns hold; there are none")
    if cols and session is not None and unit != "counts":
        raise f.err("source.reading_unit", f"the simulated calibration session reads ADC counts, "
                    f"but source.counts_columns hold {unit!r}")
    if cols and cal_file is not None:
        from calibration.store import read_document

        cal_unit = read_document(cal_file).get("reading_unit")
        if cal_unit != unit:
            raise f.err("calibration.file", f"{cal_file.name} converts readings in {cal_unit!r}, but "
                        f"source.counts_columns hold {unit!r} (source.reading_unit); give a "
                        f"calibration fitted to {unit!r} readings or set source.reading_unit")
    out = f.table(data, "outputs")
    f.known(out, {"want", "reports", "dir", "regenerate_shipped"}, "outputs")
    want = out.get("want", [])
    if not isinstance(want, list) or not all(isinstance(w, str) for w in want):
        raise f.err("outputs.want", f"expected a list of output names, got {want!r}")
    from torquebench.stages.registry import scene_outputs

    OUTPUTS = scene_outputs()                 # what the stage declarations let a scene ask for
    for w in want:
        if w not in OUTPUTS:
            raise f.err("outputs.want", f"unknown output {w!r}{_nearest(w, OUTPUTS)} "
                        f"(known: {', '.join(OUTPUTS)})")
    areas, report_dir, shipped = _report_fields(f, out, "report" in want)
    return ChainSpec(design, spn, sensor_file, gain, cal_file, session, log_file, tuple(cols),
                     tuple(want), unit, areas, report_dir, shipped)


def report_areas_available() -> list[str]:
    """The report builders: every module torquebench/reports/<area>.py (not imported here)."""
    import pkgutil

    import torquebench.reports

    return sorted(i.name for i in pkgutil.iter_modules(torquebench.reports.__path__)
                  if not i.name.startswith("_"))


def _report_fields(f: _Fields, out: dict, wanted: bool):
    """[outputs] reports / dir / regenerate_shipped: which builders, and where they write."""
    given = sorted(set(out) & {"reports", "dir", "regenerate_shipped"})
    if given and not wanted:
        raise f.err(f"outputs.{given[0]}", "is about reports, but outputs.want has no \"report\"")
    areas = None
    if "reports" in out:
        areas = out["reports"]
        known = report_areas_available()
        if not isinstance(areas, list) or not areas or not all(isinstance(a, str) for a in areas):
            raise f.err("outputs.reports", f"expected a non-empty list of report areas, got {areas!r}")
        for a in areas:
            if a not in known:
                raise f.err("outputs.reports", f"unknown report area {a!r}{_nearest(a, known)} "
                            f"(known: {', '.join(known)})")
        areas = tuple(dict.fromkeys(areas))
    shipped = out.get("regenerate_shipped", False)
    if not isinstance(shipped, bool):
        raise f.err("outputs.regenerate_shipped", f"expected true or false, got {shipped!r}")
    shipped_dir = (REPO_ROOT / "reports").resolve()
    if "dir" in out:
        report_dir = Path(f.string(out, "dir", "outputs"))
        if shipped and report_dir.resolve() != shipped_dir:
            raise f.err("outputs.regenerate_shipped", f"writes the shipped {shipped_dir}; "
                        "drop outputs.dir or this flag")
    else:
        report_dir = shipped_dir if shipped else None
    if report_dir is not None and report_dir.resolve() == shipped_dir and not shipped:
        raise f.err("outputs.dir", f"{report_dir} is the shipped reports directory; set "
                    "outputs.regenerate_shipped = true to replace the shipped reports")
    if report_dir is not None and report_dir.exists() and not report_dir.is_dir():
        raise f.err("outputs.dir", f"{report_dir} exists and is not a directory")
    return areas, report_dir, shipped


def _nearest(key, allowed) -> str:
    from userio.fields import nearest
    return nearest(key, allowed)


