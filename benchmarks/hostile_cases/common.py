"""What every class of hostile case shares: the checkout under test and the stage cache (set by
hostile_pass.main), the fixture work directory a case starts from, the ``Case`` record, and
the edits that turn a valid input into a hostile one.
"""

from __future__ import annotations

import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path


REPO = Path(__file__).resolve().parents[2]       # the checkout under test (--repo)
PY = sys.executable
SHARED_CACHE = None                               # one stage cache for every case (set in main)


def build_fixture(root: Path) -> Path:
    """The template work directory every case starts from (copied per case)."""
    import numpy as np
    import pandas as pd

    fx = root / "fixture"
    fx.mkdir()
    for stem in ("paper_fixed_link2", "paper_floating_link1"):
        for suf in (".csv", ".timing.toml", ".noise.toml"):
            src = REPO / "examples" / "sim" / f"{stem}{suf}"
            shutil.copy(src, fx / f"{'fixed' if 'fixed' in stem else 'float'}{suf}")
    shutil.copy(REPO / "examples" / "leg_poke" / "leg_poke.csv", fx / "poke.csv")
    shutil.copy(REPO / "robots" / "paper_leg.toml", fx / "robot.toml")
    scene = (REPO / "scenes" / "paper_fixed_link1.toml").read_text()
    scene = scene.replace('robot = "paper_leg.toml"', 'robot = "robot.toml"')
    scene = scene.replace("duration_s = 1.5", "duration_s = 0.3")
    scene = scene.replace("t_on_s = 0.5", "t_on_s = 0.1").replace("t_off_s = 1.0", "t_off_s = 0.2")
    (fx / "scene.toml").write_text(scene)
    shutil.copy(REPO / "sensors" / "paper_sensor.toml", fx / "sensor.toml")
    design = (REPO / "designs" / "paper_disc.toml").read_text().replace(
        'sensor = "../sensors/paper_sensor.toml"', 'sensor = "sensor.toml"')
    (fx / "design.toml").write_text(design)
    shutil.copy(REPO / "calibration" / "data" / "paper_link1_session.csv", fx / "session.csv")
    shutil.copy(REPO / "calibration" / "data" / "paper_link1_cal.json", fx / "cal.json")
    shutil.copy(REPO / "calibration" / "data" / "paper_link1_readings.csv", fx / "readings.csv")
    (fx / "notes.md").write_text("# my notes\nnever lose these\n")
    (fx / "existing.csv").write_text("t,x\n0,1\n")
    (fx / "existing.png").write_bytes(b"\x89PNG user picture")
    # a tiny end-to-end scene (no FEM, no report) for run/compare/sweep
    e2e = (REPO / "scenes" / "paper_floating_link2.toml").read_text()
    (fx / "e2e.toml").write_text(e2e.replace("duration_s = 1.5", "duration_s = 0.8"))
    # identification: an excitation log and its side files; a URDF robot and one of its 3-D logs
    for suf in (".csv", ".timing.toml", ".noise.toml"):
        shutil.copy(REPO / "examples" / "identification" / f"excitation{suf}", fx / f"excite{suf}")
        shutil.copy(REPO / "examples" / "spatial" / f"leg_pokes{suf}", fx / f"leg3d{suf}")
    for suf in (".urdf", ".toml"):
        shutil.copy(REPO / "robots" / f"quadruped_leg{suf}", fx / f"quad{suf}")
    q = (fx / "quad.toml").read_text().replace("quadruped_leg.urdf", "quad.urdf")
    (fx / "quad.toml").write_text(q)
    del np, pd
    return fx


@dataclass
class Case:
    cls: str
    name: str
    argv: list
    setup: object = None            # setup(work: Path) -> None
    expect: str = "refuse"          # refuse | ok | error | interrupt | any
    force: bool = False             # the argv asks to replace its named outputs
    outputs: tuple = ()             # named outputs (relative to work) that --force may replace
    sigint_after: float | None = None
    needs: str = ""                 # "rofs" | "fullfs": skipped when those mounts are missing
    env: dict = field(default_factory=dict)


LOGS = {"fixed": 2, "float": 2, "poke": 2}


INPUT_FILES = ["fixed.csv", "fixed.timing.toml", "fixed.noise.toml", "robot.toml", "scene.toml",
               "cal.json", "session.csv", "readings.csv", "design.toml", "sensor.toml", "notes.md"]


def csv_edit(src, dst, fn):
    def setup(work: Path):
        import pandas as pd

        d = pd.read_csv(work / src)
        d = fn(d)
        d.to_csv(work / dst, index=False, float_format="%.10g")
    return setup


def text_edit(src, dst, fn):
    def setup(work: Path):
        (work / dst).write_text(fn((work / src).read_text()))
    return setup


def chain(*fns):
    def setup(work: Path):
        for f in fns:
            if f is not None:
                f(work)
    return setup


def csv_edit_commented(src, dst, fn):
    def setup(work: Path):
        import io

        import pandas as pd

        text = (work / src).read_text()
        head = [ln for ln in text.splitlines() if ln.startswith("#")]
        d = pd.read_csv(io.StringIO(text), comment="#")
        d = fn(d)
        (work / dst).write_text("\n".join(head) + "\n" + d.to_csv(index=False))
    return setup


def scale_cols(cols, k):
    def fn(d):
        d[cols] = d[cols] * k
        return d
    return fn


def swap(a, b):
    def fn(d):
        d[[a, b]] = d[[b, a]].to_numpy()
        return d
    return fn


def const(col, v):
    def fn(d):
        d[col] = v
        return d
    return fn


def alias(rng, work_name: str):
    """(argv path, setup) naming ``work_name`` another way: plain, ./, sub/.., absolute (late bound),
    a symlink or a hard link created in the work dir."""
    kind = rng.choice(["plain", "dot", "dotdot", "symlink", "hardlink", "dirsymlink"])
    if kind == "plain":
        return work_name, None, kind
    if kind == "dot":
        return f"./{work_name}", None, kind
    if kind == "dotdot":
        return f"sub/../{work_name}", lambda w: (w / "sub").mkdir(exist_ok=True), kind
    if kind == "symlink":
        return f"link_{work_name}", lambda w: os.symlink(work_name, w / f"link_{work_name}"), kind
    if kind == "hardlink":
        return f"hard_{work_name}", lambda w: os.link(w / work_name, w / f"hard_{work_name}"), kind
    return f"dl/{work_name}", lambda w: os.symlink(".", w / "dl"), kind
