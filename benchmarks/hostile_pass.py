"""An adversarial pass over all 17 subcommands: a few hundred hostile inputs per class, each run
as a real `torquebench` process in a fresh work directory, and its outcome classified.

    python benchmarks/hostile_pass.py [--seed 1] [--jobs 2] [--only CLASS] [--match TEXT] [--limit N] [--json OUT]

Classes of input (each generated from a seed, so a second seed gives fresh inputs of the same kinds):
  paths      outputs that are inputs under another name (sidecars, symlinks, hard links, ``..``),
             existing files without --force, scene names that are paths, cache dirs with user files,
             .part captures that are symlinks, directories and device nodes as outputs
  nonsense   logs in wrong units or with swapped/dead channels, absurd options and file fields
  oserror    read-only or full file systems, device/directory inputs, unresolvable hosts,
             hash-valid files with wrong types
  runaway    huge headers/files/devices, huge sizes (walkers, rows, n_avg, thin walls, gains)
  interrupt  Ctrl-C (SIGINT) part-way through long commands
  valid      controls: ordinary inputs that must still work (exit 0)

Outcomes (first that applies):
  runaway     over the time limit (--timeout) or the memory cap (--max-rss-gb): killed
  traceback   a Python traceback on stderr, "internal error", exit 1, or killed by a signal
  data_loss   a file that existed before changed or vanished (except a named output replaced with
              --force), or a file appeared outside the case's work directory
  unclear     exit 2 with more or less than one line on stderr, or "not found" for a path that
              exists; an interrupt that does not end with exit 130 and one line
  silent      nonsense input answered with exit 0 and no "warning" anywhere in the output
  refused_valid  a control case that did not exit 0
  ok          anything else (exit 2 with one line; exit 0 with a warning; a control that worked)

Mounts a small read-only and a full tmpfs when it can (root with CAP_SYS_ADMIN), else skips those
cases. Prints the counts per class × outcome, and writes every case's record with --json.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]       # the checkout under test (--repo)
PY = sys.executable
SHARED_CACHE = None                               # one stage cache for every case (set in main)


# ------------------------------------------------------------------------------------- fixtures
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


def _csv_edit(src, dst, fn):
    def setup(work: Path):
        import pandas as pd

        d = pd.read_csv(work / src)
        d = fn(d)
        d.to_csv(work / dst, index=False, float_format="%.10g")
    return setup


def _text_edit(src, dst, fn):
    def setup(work: Path):
        (work / dst).write_text(fn((work / src).read_text()))
    return setup


def _chain(*fns):
    def setup(work: Path):
        for f in fns:
            if f is not None:
                f(work)
    return setup


# ------------------------------------------------------------------------------------- generators
LOGS = {"fixed": 2, "float": 2, "poke": 2}
INPUT_FILES = ["fixed.csv", "fixed.timing.toml", "fixed.noise.toml", "robot.toml", "scene.toml",
               "cal.json", "session.csv", "readings.csv", "design.toml", "sensor.toml", "notes.md"]


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


def gen_paths(rng) -> list[Case]:
    cases = []
    # estimate --out over an input (sidecars, robot, the log) named any way
    for _ in range(22):
        target = rng.choice(["fixed.csv", "fixed.timing.toml", "fixed.noise.toml", "robot.toml"])
        p, setup, kind = alias(rng, target)
        argv = ["estimate", "fixed.csv", "--out", p, "--robot", "robot.toml"]
        force = rng.random() < 0.7
        cases.append(Case("paths", f"estimate --out={target} via {kind}", argv + (["--force"] if force else []),
                          setup, "error", force))
    # simulate: --out such that the truth/timing/noise names an input, or --out is an input
    for _ in range(14):
        choice = rng.choice(["robot_as_truth", "scene_as_out", "robot_as_timing", "sensor_as_noise", "log_link"])
        force = rng.random() < 0.6
        if choice == "robot_as_truth":      # scene robot = x.truth.csv; simulate --out x.csv
            setup = _chain(lambda w: shutil.copy(w / "robot.toml", w / "sim.truth.csv"),
                           _text_edit("scene.toml", "scene.toml",
                                      lambda s: s.replace('robot = "robot.toml"', 'robot = "sim.truth.csv"')))
            # a robot file named .csv is refused by the robot loader? it is TOML text: fine
            argv = ["simulate", "scene.toml", "--out", "sim.csv"]
        elif choice == "scene_as_out":
            p, s2, kind = alias(rng, "scene.toml")
            setup, argv = s2, ["simulate", "scene.toml", "--out", p]
        elif choice == "robot_as_timing":
            setup = _chain(lambda w: shutil.copy(w / "robot.toml", w / "sim.timing.toml"),
                           _text_edit("scene.toml", "scene.toml",
                                      lambda s: s.replace('robot = "robot.toml"', 'robot = "sim.timing.toml"')))
            argv = ["simulate", "scene.toml", "--out", "sim.csv"]
        elif choice == "sensor_as_noise":
            setup = _chain(lambda w: shutil.copy(w / "robot.toml", w / "sim.noise.toml"),
                           _text_edit("scene.toml", "scene.toml",
                                      lambda s: s.replace('robot = "robot.toml"', 'robot = "sim.noise.toml"')))
            argv = ["simulate", "scene.toml", "--out", "sim.csv"]
        else:
            p, s2, kind = alias(rng, "robot.toml")
            setup, argv = s2, ["simulate", "scene.toml", "--out", p.replace(".toml", ".csv") if rng.random() < 0.3 else p]
        cases.append(Case("paths", f"simulate {choice}", argv + (["--force"] if force else []), setup, "error", force))
    # calibrate / apply over inputs
    for _ in range(12):
        target = rng.choice(["session.csv", "cal.json", "readings.csv", "notes.md"])
        p, setup, kind = alias(rng, target)
        force = rng.random() < 0.6
        if rng.random() < 0.5:
            out = p if not p.endswith(".csv") else p
            argv = ["calibrate", "session.csv", "--out", out, "--max-steps", "3000", "--walkers", "16"]
            if target == "notes.md":        # the report of cal → notes.md
                argv[3] = p.replace("notes.md", "notes.json")
        else:
            argv = ["apply", "cal.json", "readings.csv", "--out", p]
        cases.append(Case("paths", f"{argv[0]} over {target} via {kind}", argv + (["--force"] if force else []),
                          setup, "error", force))
    # existing user files at an output path, without --force (must be kept)
    for cmd in (["estimate", "fixed.csv", "--out", "existing.csv"],
                ["apply", "cal.json", "readings.csv", "--out", "existing.csv"],
                ["propagate", "--grid", "2", "--draws", "20", "--png", "existing.png"],
                ["compare", "e2e.toml", "--vary", "sensors.seed=1,2", "--png", "existing.png"],
                ["compare", "e2e.toml", "--vary", "sensors.seed=1,2", "--png", "e2e.toml"],
                ["simulate", "scene.toml", "--out", "existing.csv"],
                ["acquire", "--port", "loop://", "--out", "existing.csv", "--duration-s", "0.3"],
                ["acquire", "--port", "loop://", "--out", "cap.bin", "--csv", "existing.csv", "--duration-s", "0.3"]):
        cases.append(Case("paths", f"{cmd[0]} over an existing file", cmd, None, "error"))
    # demo / report / reproduce --out-dir holding the user's files of the same names
    for _ in range(6):
        name = rng.choice(["log.csv", "log.truth.csv", "estimate_dynamic.csv", "estimate_paper.csv"])
        cases.append(Case("paths", f"demo --out-dir with the user's {name}", ["demo", "--out-dir", "od"],
                          lambda w, n=name: ((w / "od").mkdir(), (w / "od" / n).write_text("mine\n")), "error"))
    for name in ("bridge.md", "bridge_noise.png", "README.md"):
        cases.append(Case("paths", f"report --out-dir with the user's {name}",
                          ["report", "--only", "bridge", "--out-dir", "od"],
                          lambda w, n=name: ((w / "od").mkdir(), (w / "od" / n).write_text("mine\n")), "error"))
    cases.append(Case("paths", "reproduce --out-dir with the user's report",
                      ["reproduce", "--scene", "paper_fixed_link1", "--no-stiffness", "--out-dir", "od"],
                      lambda w: ((w / "od").mkdir(), (w / "od" / "paper_reproduction.md").write_text("mine\n")),
                      "error"))
    # scene names that are paths, or the name of a user's file in the report dir
    for _ in range(10):
        name = rng.choice(["../../escaped", "../escaped", "/tmp/escaped_abs", "notes", "sub/../../x",
                           "..", ".", "a/b", "e2e", "..\\\\x"])
        def setup(w, name=name):
            s = (w / "e2e.toml").read_text()
            s = s.replace('name = "paper_floating_link2"', f'name = "{name}"')
            s += '\n[outputs]\nwant = ["report"]\nreports = ["bridge"]\ndir = "."\n' if rng.random() < 0.5 else \
                 '\n[outputs]\nwant = ["report"]\nreports = ["bridge"]\n'
            (w / "named.toml").write_text(s)
        cases.append(Case("paths", f"run scene name {name!r}", ["run", "named.toml"], setup, "any"))
    # cache clear on a directory holding the user's own .pkl files
    for _ in range(5):
        cases.append(Case("paths", "cache clear --cache-dir with user files",
                          ["cache", "clear", "--cache-dir", "mine"],
                          lambda w: ((w / "mine").mkdir(), (w / "mine" / "model.pkl").write_bytes(b"user"),
                                     (w / "mine" / f"{'a' * 64}.pkl").write_bytes(b"also user")), "any"))
    # acquire: an existing .part (kept by an interrupted run) and a .part that is a symlink
    cases.append(Case("paths", "acquire with a kept .part", ["acquire", "--port", "loop://", "--out", "cap.bin",
                                                             "--duration-s", "0.3"],
                      lambda w: (w / "cap.bin.part").write_bytes(b"\xa5\x5a earlier capture"), "any",
                      outputs=("cap.bin.part",)))      # moved into cap.bin with the new bytes appended
    cases.append(Case("paths", "acquire .part symlink onto notes", ["acquire", "--port", "loop://", "--out", "cap.bin",
                                                                    "--duration-s", "0.3"],
                      lambda w: os.symlink("notes.md", w / "cap.bin.part"), "any"))
    cases.append(Case("paths", "acquire .part symlink onto notes --force",
                      ["acquire", "--port", "loop://", "--out", "cap.bin", "--duration-s", "0.3", "--force"],
                      lambda w: os.symlink("notes.md", w / "cap.bin.part"), "any", True))
    # outputs that are directories or device nodes
    for cmd in (["estimate", "fixed.csv", "--out", "{dev}"], ["apply", "cal.json", "readings.csv", "--out", "{dev}"],
                ["simulate", "scene.toml", "--out", "{dev}"], ["estimate", "fixed.csv", "--out", "adir"],
                ["propagate", "--grid", "2", "--draws", "20", "--png", "{dev}"]):
        force = rng.random() < 0.5
        def setup(w):
            (w / "adir").mkdir()
            os.mknod(w / "nulldev", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        argv = [a.replace("{dev}", "nulldev") for a in cmd] + (["--force"] if force else [])
        cases.append(Case("paths", f"{cmd[0]} --out a device/dir", argv, setup, "error", force))
    # a file created at --out while the run is going (not replaced without --force)
    cases.append(Case("paths", "estimate --out appears during the run",
                      ["estimate", "float.csv", "--out", "late.csv", "--chunk-samples", "64"],
                      None, "any", env={"HOSTILE_LATE_FILE": "late.csv"}))
    return cases


def _scale_cols(cols, k):
    def fn(d):
        d[cols] = d[cols] * k
        return d
    return fn


def _swap(a, b):
    def fn(d):
        d[[a, b]] = d[[b, a]].to_numpy()
        return d
    return fn


def _const(col, v):
    def fn(d):
        d[col] = v
        return d
    return fn


def gen_nonsense(rng) -> list[Case]:
    cases = []
    # logs in wrong units / swapped / dead
    transforms = [
        ("tau in N·mm", lambda: _scale_cols(["tau1", "tau2"], 1000.0)),
        ("tau in kN·m", lambda: _scale_cols(["tau1", "tau2"], 1e-3)),
        ("wrench in kN", lambda: _scale_cols(["Fx", "Fz", "My"], 1e-3)),
        ("wrench in mN", lambda: _scale_cols(["Fx", "Fz", "My"], 1e3)),
        ("Fx/Fz swapped", lambda: _swap("Fx", "Fz")),
        ("tau1/tau2 swapped", lambda: _swap("tau1", "tau2")),
        ("dead tau2", lambda: _const("tau2", 0.0)),
        ("dead tau1", lambda: _const("tau1", 0.0)),
        ("dead Fz", lambda: _const("Fz", 0.0)),
        ("constant Fz", lambda: _const("Fz", 3.0)),
        ("all zero", lambda: (lambda d: d.assign(**{c: 0.0 for c in d.columns if c != "t"}))),
        ("angles in degrees", lambda: _scale_cols(["q1", "q2"], 57.29577951308232)),
        ("rates in deg/s", lambda: _scale_cols(["dq1", "dq2"], 57.29577951308232)),
        ("Fz sign flipped", lambda: _scale_cols(["Fz"], -1.0)),
        ("torques sign flipped", lambda: _scale_cols(["tau1", "tau2"], -1.0)),
        ("My in N·mm", lambda: _scale_cols(["My"], 1000.0)),
        ("random channel ×1e3", None),
        ("random channel ×1e-3", None),
    ]
    for _ in range(70):
        label, make = rng.choice(transforms)
        log = rng.choice(["fixed", "float", "poke"])
        if make is None:
            col = rng.choice(["tau1", "tau2", "Fx", "Fz", "My"])
            fn = _scale_cols([col], 1e3 if "×1e3" in label else 1e-3)
            label = label.replace("random channel", col)
        else:
            fn = make()
        if log == "float" and "angles" in label and rng.random() < 0.5:
            fn = _scale_cols(["q1", "q2", "theta"], 57.29577951308232)
        argv = ["estimate", "bad.csv"] + (["--json"] if rng.random() < 0.3 else []) + \
            (["--method", "paper"] if rng.random() < 0.2 else [])
        cases.append(Case("nonsense", f"estimate {log} log with {label}", argv,
                          _csv_edit(f"{log}.csv", "bad.csv", fn), "refuse"))
    # absurd estimate options
    opts = [("--gain", ["1e-300", "1e-9", "1e9", "1e300", "1e-6"]),
            ("--torque-sigma", ["1e300", "1e-300", "1e-30", "1e30", "1e6,1e-300"]),
            ("--ft-sigma", ["1e300,1e300,1e300", "1e-300,0.1,0.01", "0.1,0.1,1e300", "1e-30,1e-30,1e-30"]),
            ("--velocity-sigma", ["1e300", "1e30"]),
            ("--encoder-counts", ["1e300", "0.5", "1e30", "3"]),
            ("--timing", ["delay:1e300", "delay:100", "delay:1e9", "delay:5", "delay:1e-300x"]),
            ("--false-alarm-rate", ["1e-300/h", "1e-300/sample", "1e300/h"]),
            ("--threshold", ["1e300", "1e-300"]),
            ("--quiet-window", ["0.55:0.95", "0.6:0.9", "0.5:1.0", "0.3:1.2", "0:1.5", "0.4:1.1"])]
    for _ in range(50):
        opt, vals = rng.choice(opts)
        v = rng.choice(vals)
        log = "fixed" if opt == "--quiet-window" else rng.choice(["fixed", "float"])
        cases.append(Case("nonsense", f"estimate {opt} {v}", ["estimate", f"{log}.csv", f"{opt}={v}"], None,
                          "refuse"))
    # sidecars and robot files with absurd fields
    sidecars = [("fixed.timing.toml", "[timing]\ndefault = \"delay:100\"\n"),
                ("fixed.timing.toml", "[timing]\nwrench = \"delay:1e300\"\n"),
                ("fixed.timing.toml", "[timing]\ntau = \"delay:1e9\"\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [1e300]\nft_sigma = [0.1, 0.1, 0.01]\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [1e-300]\nft_sigma = [0.1, 0.1, 0.01]\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [0.01]\nft_sigma = [1e-300, 1e-300, 1e-300]\n"),
                ("fixed.noise.toml", "[noise]\ntorque_sigma_Nm = [0.01]\nft_sigma = [0.1, 0.1, 0.01]\n"
                                     "encoder_counts = 1000000000000000000\n")]
    for _ in range(14):
        name, text = rng.choice(sidecars)
        cases.append(Case("nonsense", f"estimate with {name}: {text.splitlines()[-1][:40]}",
                          ["estimate", "fixed.csv"], lambda w, n=name, t=text: (w / n).write_text(t), "refuse"))
    robot_edits = [("length_m = 0.205", "length_m = 1e300"), ("length_m = 0.205", "length_m = 205.0"),
                   ("length_m = 0.215", "length_m = 1e-300"), ("mass_kg = 0.351", "mass_kg = 1e300"),
                   ("mass_kg = 0.351", "mass_kg = 351.0"), ("mass_kg = 0.080", "mass_kg = 1e-12"),
                   ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 0.0"),
                   ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 9810.0"),
                   ("gravity_m_per_s2 = 9.81", "gravity_m_per_s2 = 1e-300"),
                   ("inertia_kgm2 = 0.00207", "inertia_kgm2 = 1e300"),
                   ("inertia_kgm2 = 0.00207", "inertia_kgm2 = 2070.0"),
                   ("stiffness = [5000.0, 5000.0, 500.0]", "stiffness = [1e300, 5000.0, 500.0]"),
                   ("com_m = 0.171", "com_m = 171.0")]
    for _ in range(26):
        a, b = rng.choice(robot_edits)
        cmd = rng.choice([["estimate", "float.csv", "--robot", "robot.toml"],
                          ["simulate", "scene.toml", "--out", "o.csv"],
                          ["propagate", "--robot", "robot.toml", "--grid", "2", "--draws", "20"]])
        cases.append(Case("nonsense", f"{cmd[0]} robot {b}", cmd,
                          _text_edit("robot.toml", "robot.toml", lambda s, a=a, b=b: s.replace(a, b, 1)), "refuse"))
    scene_edits = [("kp = 500.0", "kp = 1e12"), ("kp = 500.0", "kp = 1e300"), ("kd = 10.0", "kd = 1e300"),
                   ("q0_rad = [-0.4, -0.8]", "q0_rad = [-23.0, -46.0]"),
                   ("q0_rad = [-0.4, -0.8]", "q0_rad = [-0.4, -0.8]\namplitude_rad = [0.1, 0.1]\nfrequency_Hz = [1e6, 1e6]"),
                   ("t_on_s = 0.1", "t_on_s = 5.0"), ("t_off_s = 0.2", "t_off_s = 50.0"),
                   ("magnitude_N = 5.0", "magnitude_N = 1e300"), ("magnitude_N = 5.0", "magnitude_N = 5e6"),
                   ("sample_rate_Hz = 1000.0", "sample_rate_Hz = 1e9"),
                   ("sample_rate_Hz = 1000.0", "sample_rate_Hz = 1e-3"),
                   ("ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [1e300, 0.1, 0.01]"),
                   ("ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [1e-300, 1e-300, 1e-300]"),
                   ('torque_model = "bridge"', 'torque_model = "gaussian"\ntorque_noise_Nm = 1e300'),
                   ("duration_s = 0.3", "duration_s = 1e9"), ("seed = 11", "seed = -1"),
                   ("rtol = 1e-6", "rtol = 1e-300")]
    for _ in range(30):
        a, b = rng.choice(scene_edits)
        cmd = rng.choice([["simulate", "scene.toml", "--out", "o.csv"], ["run", "scene.toml", "--only", "estimates"]])
        cases.append(Case("nonsense", f"{cmd[0]} scene {b.splitlines()[-1]}", cmd,
                          _text_edit("scene.toml", "scene.toml", lambda s, a=a, b=b: s.replace(a, b, 1)), "refuse"))
    # calibrate / apply / acquire
    cal_cases = [
        (["calibrate", "session.csv", "--out", "c.json", "--lever-arm-m", "205"], None),
        (["calibrate", "session.csv", "--out", "c.json", "--lever-arm-m", "1e300"], None),
        (["calibrate", "session.csv", "--out", "c.json", "--lever-arm-m", "1e-300"], None),
        (["calibrate", "session.csv", "--out", "c.json", "--mass-std-g", "1e300"], None),
        (["calibrate", "lever.csv", "--out", "c.json"],
         _text_edit("session.csv", "lever.csv", lambda s: s.replace(",0.205,", ",205,"))),
        (["calibrate", "lever.csv", "--out", "c.json"],
         _text_edit("session.csv", "lever.csv", lambda s: s.replace(",0.205,", ",1e300,"))),
        (["apply", "cal.json", "counts.csv"],
         _text_edit("readings.csv", "counts.csv", lambda s: s.replace("reading_unit=mV", "reading_unit=counts"))),
        (["apply", "cal.json", "counts.csv"],
         _csv_edit_commented("readings.csv", "counts.csv", lambda d: d.assign(reading=d["reading"] * 8.4e5))),
        (["acquire", "--port", "loop://", "--out", "cap.bin", "--guided", "0,10", "--lever-arm-m", "205"], None),
        (["propagate", "--contact", "2,0.8,1", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--contact", "2,0.8,1,7", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--force", "7,1,3", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--gain", "1e-300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--rate", "1e-9", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--ft-noise", "1e300,1e300,1e300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--ft-noise", "1e-300,1e-300,1e-300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--torque-noise-Nm", "1e-300", "--grid", "2", "--draws", "20"], None),
        (["propagate", "--force", "1e300,0", "--grid", "2", "--draws", "20"], None),
        (["bridge", "--bandwidth-Hz", "1e300"], None),
        (["bridge", "--strain-per-Nm", "1e-300"], None),
        (["bridge", "--averaging", "1000000000000"], None),
        (["bridge", "s2.toml"], _text_edit("sensor.toml", "s2.toml", lambda s: s.replace("gain = 1.0", "gain = 1e300"))),
        (["bridge", "s2.toml"], _text_edit("sensor.toml", "s2.toml", lambda s: s.replace("excitation_V = 5.0", "excitation_V = 5e6"))),
        (["bridge", "s2.toml"], _text_edit("sensor.toml", "s2.toml", lambda s: s.replace("gain = 1.0", "gain = 1e-300"))),
        (["bridge", "s2.toml"], _text_edit("sensor.toml", "s2.toml", lambda s: s.replace("temperature_K = 300.0", "temperature_K = 1e300"))),
        (["flexure", "d2.toml", "--single-level"], _text_edit("design.toml", "d2.toml",
                                                             lambda s: s.replace('preset = "6061-T6"', 'preset = "6061-T6"\nE_GPa = 68.9e9'))),
        (["flexure", "d2.toml", "--single-level"], _text_edit("design.toml", "d2.toml",
                                                             lambda s: s.replace("thickness_mm = 2.2", "thickness_mm = 1e300"))),
        (["flexure", "d2.toml", "--single-level"], _text_edit("design.toml", "d2.toml",
                                                             lambda s: s.replace("rated_torque_Nm = 2.0", "rated_torque_Nm = 1e300"))),
        (["simulate", "scene.toml", "--out", "o.csv", "--duration", "1e9"], None),
        (["run", "scene.toml", "--seed", "-1", "--only", "estimates"], None),
        (["run", "e2e.toml", "--seed", "-1"], None),
        (["demo", "--seed", "-1"], None),
    ]
    for argv, setup in cal_cases:
        cases.append(Case("nonsense", " ".join(argv[:1] + argv[2:])[:70], argv, setup, "refuse"))
    # compare / sweep: every point failing must not exit 0
    for cmd in ("compare", "sweep"):
        for vary in ("sensors.sample_rate_Hz=-1,-2", "controller.kp=-5", "nosuch.key=1,2"):
            cases.append(Case("nonsense", f"{cmd} all points fail {vary}",
                              [cmd, "e2e.toml", "--vary", vary, "--executor", "local"], None, "error"))
    return cases


def _csv_edit_commented(src, dst, fn):
    def setup(work: Path):
        import io

        import pandas as pd

        text = (work / src).read_text()
        head = [ln for ln in text.splitlines() if ln.startswith("#")]
        d = pd.read_csv(io.StringIO(text), comment="#")
        d = fn(d)
        (work / dst).write_text("\n".join(head) + "\n" + d.to_csv(index=False))
    return setup


def gen_oserror(rng, mounts) -> list[Case]:
    cases = []
    writers = [
        ["estimate", "fixed.csv", "--out", "{D}/e.csv"],
        ["simulate", "scene.toml", "--out", "{D}/s.csv"],
        ["calibrate", "session.csv", "--out", "{D}/c.json", "--walkers", "16", "--max-steps", "3000"],
        ["apply", "cal.json", "readings.csv", "--out", "{D}/a.csv"],
        ["propagate", "--grid", "2", "--draws", "20", "--png", "{D}/p.png"],
        ["demo", "--out-dir", "{D}/demo"],
        ["report", "--only", "bridge", "--out-dir", "{D}/rep"],
        ["reproduce", "--scene", "paper_fixed_link1", "--no-stiffness", "--out-dir", "{D}/repro"],
        ["acquire", "--port", "loop://", "--out", "{D}/cap.bin", "--duration-s", "0.2"],
        ["run", "scene.toml", "--only", "estimates", "--cache-dir", "{D}/cache"],
        ["cache", "info", "--cache-dir", "{D}/cache"],
        ["compare", "e2e.toml", "--vary", "sensors.seed=1", "--png", "{D}/c.png"],
        ["flexure", "--single-level", "--png", "{D}/f.png"],
    ]
    for which in ("rofs", "fullfs"):
        for argv in writers:
            d = mounts.get(which)
            a = [x.replace("{D}", d or "/nonexistent") for x in argv]
            cases.append(Case("oserror", f"{argv[0]} on a {which}", a, None, "error", needs=which))
    # the cache directory is a file; the default cache dir is a file
    cases.append(Case("oserror", "run --cache-dir is a file", ["run", "scene.toml", "--only", "estimates",
                                                               "--cache-dir", "notes.md"], None, "error"))
    cases.append(Case("oserror", "cache info --cache-dir is a file", ["cache", "info", "--cache-dir", "notes.md"],
                      None, "any"))
    cases.append(Case("oserror", "simulate with $TORQUEBENCH_CACHE a file", ["simulate", "scene.toml", "--out", "o.csv"],
                      None, "any", env={"TORQUEBENCH_CACHE": "notes.md"}))
    cases.append(Case("oserror", "sweep dask host does not resolve",
                      ["sweep", "e2e.toml", "--vary", "sensors.seed=1,2", "--executor", "dask://no.such.host.invalid:8786"],
                      None, "error"))
    # inputs that are directories or devices
    dev_inputs = [["estimate", "{X}"], ["estimate", "fixed.csv", "--robot", "{X}"], ["simulate", "{X}", "--out", "o.csv"],
                  ["calibrate", "{X}", "--out", "c.json"], ["apply", "{X}", "readings.csv"], ["apply", "cal.json", "{X}"],
                  ["bridge", "{X}"], ["flexure", "{X}"], ["run", "{X}"], ["propagate", "--calibration", "{X}"],
                  ["propagate", "--sensor", "{X}"], ["compare", "{X}", "--vary", "sensors.seed=1"]]
    for argv in dev_inputs:
        for kind in ("dir", "zero", "null"):
            def setup(w, kind=kind):
                if kind == "dir":
                    (w / "thing").mkdir()
                else:
                    os.mknod(w / "thing", 0o666 | stat.S_IFCHR, os.makedev(1, 5 if kind == "zero" else 3))
            a = [x.replace("{X}", "thing") for x in argv]
            cases.append(Case("oserror", f"{argv[0]} input is a {kind}", a, setup, "error"))
    # hash-valid files with wrong types
    for key, value in (("coefficients", "slope"), ("lever_arm_m", "0.2"), ("covariance", None), ("model", 3),
                       ("reading_unit", 5), ("samples", "abc"), ("posterior", [1, 2]), ("schema_version", "x"),
                       ("diagnostics", None), ("data", 7)):
        cases.append(Case("oserror", f"apply cal.json with {key}={value!r} and a valid hash",
                          ["apply", "bad.json", "readings.csv"], _bad_cal(key, value), "error"))
    for payload in ("str", "list", "none", "dict"):
        cases.append(Case("oserror", f"run with a hash-valid cache entry holding a {payload}",
                          ["run", "scene.toml", "--only", "estimates", "--cache-dir", "cc"], _bad_cache(payload), "any"))
    # calibration readings that break the sampler
    for label, fn in (("noise-free", lambda d: d.assign(reading=5.0 + 0.0115 * d["mass_g"])),
                      ("1e300", lambda d: d.assign(reading=d["reading"] * 1e300)),
                      ("1e-300", lambda d: d.assign(reading=d["reading"] * 1e-300)),
                      ("constant", lambda d: d.assign(reading=5.0))):
        cases.append(Case("oserror", f"calibrate {label} readings", ["calibrate", "s2.csv", "--out", "c.json",
                                                                     "--max-steps", "5000"],
                          _csv_edit_commented("session.csv", "s2.csv", fn), "any"))
    # extreme numbers that overflow
    for argv in (["estimate", "fixed.csv", "--timing", "delay:1e300"],
                 ["estimate", "fixed.csv", "--torque-sigma", "1e-300"],
                 ["estimate", "fixed.csv", "--ft-sigma", "1e-300,1e-300,1e-300"],
                 ["run", "scene.toml", "--seed", "-1"],
                 ["flexure", "d2.toml", "--single-level"]):
        setup = _text_edit("design.toml", "d2.toml", lambda s: s.replace("thickness_mm = 2.2", "thickness_mm = 1e300")) \
            if argv[0] == "flexure" else None
        cases.append(Case("oserror", " ".join(argv)[:60], argv, setup, "error"))
    return cases


def _bad_cal(key, value):
    def setup(w: Path):
        from calibration.store import encode

        doc = json.loads((w / "cal.json").read_text())
        node, *path = key.split(".")
        target = doc
        for k in [node, *path][:-1]:
            target = target[k]
        target[[node, *path][-1]] = value
        (w / "bad.json").write_bytes(encode(doc))
    return setup


def _bad_cache(payload):
    def setup(w: Path):
        import pickle

        sys.path.insert(0, str(REPO))
        from torquebench import pipeline as P
        from torquebench.cache import Cache
        from torquebench.scenes import load_scene

        os.chdir(w)
        scene = load_scene(w / "scene.toml")
        value = {"str": "x", "list": [1, 2], "none": None, "dict": {"log": 3}}[payload]
        c = Cache(w / "cc")
        for s in P.plan(scene, ["estimates"], None):
            if s.key:
                data = pickle.dumps(value)
                c.dir.mkdir(exist_ok=True)
                (c.dir / f"{s.key}.pkl").write_bytes(hashlib.sha256(data).hexdigest().encode() + b"\n" + data)
    return setup


def gen_runaway(rng) -> list[Case]:
    cases = []
    def wide(w, n=120_000):
        (w / "wide.csv").write_text(",".join(f"c{i}" for i in range(n)) + "\n" + ",".join("0" for _ in range(n)) + "\n")
    def noline(w):
        with open(w / "noline.csv", "wb") as f:
            f.write(b"t,q1," + b"9" * (300 << 20))
    def sparse(w, name, gb=3):
        with open(w / name, "wb") as f:
            f.truncate(gb << 30)
    cases += [Case("runaway", "estimate 120k-column header", ["estimate", "wide.csv"], wide, "error"),
              Case("runaway", "estimate 300 MB header line", ["estimate", "noline.csv"], noline, "error"),
              Case("runaway", "estimate /dev/zero", ["estimate", "/dev/zero"], None, "error"),
              Case("runaway", "estimate a 3 GB sparse file", ["estimate", "big.csv"], lambda w: sparse(w, "big.csv"), "error"),
              Case("runaway", "calibrate /dev/zero", ["calibrate", "/dev/zero", "--out", "c.json"], None, "error"),
              Case("runaway", "apply readings /dev/zero", ["apply", "cal.json", "/dev/zero"], None, "error"),
              Case("runaway", "apply a 3 GB sparse readings", ["apply", "cal.json", "big.csv"], lambda w: sparse(w, "big.csv"), "error"),
              Case("runaway", "bridge /dev/zero", ["bridge", "/dev/zero"], None, "error"),
              Case("runaway", "run /dev/zero", ["run", "/dev/zero"], None, "error"),
              Case("runaway", "flexure 3 GB sparse design", ["flexure", "big.toml"], lambda w: sparse(w, "big.toml"), "error"),
              Case("runaway", "calibrate 120k-column session", ["calibrate", "wide.csv", "--out", "c.json"], wide, "error"),
              Case("runaway", "calibrate --walkers 1e7", ["calibrate", "session.csv", "--out", "c.json", "--walkers", "10000000"], None, "error"),
              Case("runaway", "calibrate --walkers 1e5", ["calibrate", "session.csv", "--out", "c.json", "--walkers", "100000"], None, "error"),
              Case("runaway", "calibrate --max-steps 1e12", ["calibrate", "session.csv", "--out", "c.json", "--max-steps", "1000000000000"], None, "any"),
              Case("runaway", "calibrate 210k rows", ["calibrate", "big.csv", "--out", "c.json"], _big_session(210_000), "error"),
              Case("runaway", "propagate --draws 1e12", ["propagate", "--draws", "1000000000000"], None, "error"),
              Case("runaway", "propagate --grid 1e6", ["propagate", "--grid", "1000000"], None, "error"),
              Case("runaway", "bridge --averaging 1e12", ["bridge", "--averaging", "1000000000000"], None, "any"),
              Case("runaway", "estimate --debounce 1e15", ["estimate", "fixed.csv", "--debounce", "1000000000000000"], None, "any"),
              Case("runaway", "estimate --chunk-samples 1e12", ["estimate", "fixed.csv", "--chunk-samples", "1000000000000"], None, "any"),
              ]
    for n_avg in ("1000000000000", "100000000"):
        cases.append(Case("runaway", f"run calibration n_avg {n_avg}", ["run", "cal_scene.toml", "--only", "calibration"],
                          _text_edit("e2e.toml", "cal_scene.toml",
                                     lambda s, n=n_avg: s + f"\n[calibration]\nn_avg = {n}\n"), "error"))
    for kp in ("1e12", "1e9", "1e15"):
        cases.append(Case("runaway", f"simulate kp {kp}", ["simulate", "scene.toml", "--out", "o.csv"],
                          _text_edit("scene.toml", "scene.toml", lambda s, kp=kp: s.replace("kp = 500.0", f"kp = {kp}")),
                          "error"))
    for edit in (("thickness_mm = 2.2", "thickness_mm = 0.2"), ("spoke_width_mm = 3.5", "spoke_width_mm = 0.05"),
                 ('preset = "6061-T6"', 'preset = "6061-T6"\nnu = 0.4999'),
                 ('preset = "6061-T6"', 'preset = "6061-T6"\nnu = 0.49999'),
                 ("outer_radius_mm = 30.0", "outer_radius_mm = 3000.0")):
        cases.append(Case("runaway", f"flexure {edit[1].splitlines()[-1]}", ["flexure", "d2.toml"],
                          _text_edit("design.toml", "d2.toml", lambda s, e=edit: s.replace(*e)), "error"))
    cases.append(Case("runaway", "sweep 1000 points (cost shown first)",
                      ["sweep", "e2e.toml", "--vary", "sensors.seed=" + ",".join(map(str, range(1000))),
                       "--executor", "local"], None, "cost"))
    cases.append(Case("runaway", "compare 400 points (cost shown first)",
                      ["compare", "e2e.toml", "--vary", "sensors.seed=" + ",".join(map(str, range(400)))], None, "cost"))
    cases.append(Case("runaway", "flexure sweep 1000 designs",
                      ["flexure", "--sweep", "spoke_width_mm=" + ",".join(f"{3 + i * 1e-3:.3f}" for i in range(1000))],
                      None, "cost"))
    return cases


def _big_session(n):
    def setup(w: Path):
        import numpy as np

        rng = np.random.default_rng(0)
        m = np.tile([10, 20, 50, 100, 200, 500, 1000], n // 7 + 1)[:n]
        r = 5.0 + 0.0115 * m + rng.normal(0, 0.01, n)
        (w / "big.csv").write_text("# reading_unit=mV\nmass_g,reading,lever_arm_m\n"
                                   + "\n".join(f"{a},{b:.6f},0.205" for a, b in zip(m, r)) + "\n")
    return setup


def gen_interrupt(rng) -> list[Case]:
    cases = []
    long = [(["calibrate", "session.csv", "--out", "c.json", "--walkers", "64"], (1.5, 6.0)),
            (["flexure", "--single-level"], (3.0, 20.0)),
            (["flexure", "--single-level", "--size", "medium"], (8.0, 20.0)),
            (["simulate", "scene.toml", "--out", "o.csv", "--duration", "3"], (1.5, 4.0)),
            (["estimate", "float.csv", "--chunk-samples", "64", "--out", "e.csv"], (1.2, 2.5)),
            (["propagate", "--grid", "6", "--draws", "2000"], (1.5, 5.0)),
            (["demo", "--out-dir", "dd"], (1.2, 3.0)),
            (["sweep", "e2e.toml", "--vary", "sensors.seed=1,2,3,4", "--executor", "processes:2"], (3.0, 8.0)),
            (["run", "e2e.toml"], (1.5, 4.0)),
            (["report", "--only", "bridge", "--out-dir", "rr"], (1.5, 3.0))]
    for _ in range(24):
        argv, (a, b) = rng.choice(long)
        cases.append(Case("interrupt", f"Ctrl-C in {' '.join(argv[:2])}", argv, None, "interrupt",
                          sigint_after=round(rng.uniform(a, b), 2)))
    return cases


def gen_identify_and_3d(rng) -> list[Case]:
    """The commands and robots that came after the first passes: `identify`, URDF robots."""
    ident = ["identify", "excite.csv", "--robot", "robot.toml"]
    cases = []
    # paths: the identified robot may not replace the log, the robot it starts from or a user file
    for target, expect in (("robot.toml", "refuse"), ("excite.csv", "refuse"), ("excite.noise.toml", "refuse"),
                           ("notes.md", "refuse")):
        p, setup, kind = alias(rng, target)
        cases.append(Case("paths", f"identify --out={target} via {kind}", ident + ["--out", p], setup, expect))
    p, setup, kind = alias(rng, "leg3d.csv")
    cases.append(Case("paths", f"estimate 3-D --out=the log via {kind}",
                      ["estimate", "leg3d.csv", "--robot", "quad.toml", "--out", p], setup, "refuse"))
    p, setup, kind = alias(rng, "quad.urdf")
    cases.append(Case("paths", f"estimate 3-D --png=the URDF via {kind}",
                      ["estimate", "leg3d.csv", "--robot", "quad.toml", "--png", p], setup, "refuse"))
    # nonsense: a log with a contact over its whole length, too short, in degrees, torques in N·mm
    k = rng.choice([1000.0, 1e-3])
    cases.append(Case("nonsense", f"identify with torques ×{k:g}", ["identify", "bad.csv", "--robot", "robot.toml"],
                      _csv_edit("excite.csv", "bad.csv", _scale_cols(["tau1", "tau2"], k)), "refuse"))
    cases.append(Case("nonsense", "identify on 40 samples", ["identify", "short.csv", "--robot", "robot.toml"],
                      _csv_edit("excite.csv", "short.csv", lambda d: d.iloc[:40]), "refuse"))
    cases.append(Case("nonsense", "identify on a poke log", ["identify", "float.csv", "--robot", "robot.toml"],
                      None, "refuse"))
    cases.append(Case("nonsense", "identify angles in degrees", ["identify", "deg.csv", "--robot", "robot.toml"],
                      _csv_edit("excite.csv", "deg.csv", _scale_cols(["q1", "q2", "dq1", "dq2"], 57.29578)),
                      "refuse"))
    cases.append(Case("nonsense", "estimate 3-D torques ×1000", ["estimate", "bad3.csv", "--robot", "quad.toml"],
                      _csv_edit("leg3d.csv", "bad3.csv", lambda d: d.assign(**{c: d[c] * 1000 for c in d.columns
                                                                              if c.startswith("tau")})),
                      "refuse"))
    cases.append(Case("nonsense", "estimate a planar log with a URDF robot", ["estimate", "fixed.csv", "--robot", "quad.toml"],
                      None, "refuse"))
    cases.append(Case("nonsense", "propagate 3-D wrong posture length",
                      ["propagate", "--robot", "quad.toml", "--posture", "0.1,0.2", "--force", "5"], None, "refuse"))
    bad_rate = rng.choice(["-1", "0", "nan", "1e300"])
    cases.append(Case("nonsense", f"estimate --model-uncertainty {bad_rate}",
                      ["estimate", "fixed.csv", "--model-uncertainty", bad_rate], None, "refuse"))
    # controls
    cases += [Case("valid", "identify the excitation log", ident + ["--out", "ident/robot_id.toml"], None, "ok"),
              Case("valid", "estimate a 3-D log", ["estimate", "leg3d.csv", "--robot", "quad.toml"], None, "ok"),
              Case("valid", "estimate with a declared model uncertainty",
                   ["estimate", "fixed.csv", "--model-uncertainty", "0.05"], None, "ok")]
    return cases


def gen_valid(rng) -> list[Case]:
    c = [["estimate", "fixed.csv"], ["estimate", "float.csv", "--json"], ["estimate", "poke.csv"],
         ["estimate", "fixed.csv", "--out", "new/e.csv"], ["estimate", "poke.csv", "--method", "paper"],
         ["estimate", "fixed.csv", "--quiet-window", "0.05:0.45"], ["estimate", "fixed.csv", "--gain", "50"],
         ["estimate", "fixed.csv", "--torque-sigma", "0.013", "--ft-sigma", "0.1,0.1,0.01"],
         ["estimate", "fixed.csv", "--timing", "delay:0.0005"],
         ["simulate", "scene.toml", "--out", "o/sim.csv"], ["bridge"], ["bridge", "sensor.toml", "--averaging", "16"],
         ["calibrate", "session.csv", "--out", "c/cal.json"], ["apply", "cal.json", "readings.csv"],
         ["apply", "cal.json", "readings.csv", "--out", "t.csv"], ["propagate", "--grid", "3", "--draws", "50"],
         ["propagate", "--contact", "1,0.5", "--grid", "2", "--draws", "20"],
         ["run", "scene.toml", "--only", "estimates"], ["run", "e2e.toml", "--explain"], ["cache", "info"],
         ["cache", "clear"], ["demo", "--out-dir", "d"], ["report", "--list"],
         ["report", "--only", "bridge", "--out-dir", "newrep"],
         ["acquire", "--port", "loop://", "--out", "cap.bin", "--duration-s", "0.3"],
         ["compare", "e2e.toml", "--vary", "sensors.seed=1,2", "--png", "cmp.png"],
         ["sweep", "e2e.toml", "--vary", "sensors.seed=1,2", "--executor", "local"],
         ["reproduce", "--scene", "paper_fixed_link1", "--no-stiffness", "--out-dir", "rp"],
         ["flexure", "--single-level"]]
    cases = [Case("valid", " ".join(a)[:70], a, None, "ok") for a in c]
    # repeated run into the same --out-dir: the demo's own files are its to replace
    cases.append(Case("valid", "demo twice into one --out-dir", ["demo", "--out-dir", "d2"],
                      lambda w: subprocess.run([PY, "-m", "torquebench", "demo", "--out-dir", "d2"], cwd=w,
                                               capture_output=True, env=_env(w)), "ok",
                      outputs=tuple(f"d2/{n}" for n in ("log.csv", "log.truth.csv", "estimate_dynamic.csv",
                                                        "estimate_paper.csv", ".torquebench-outputs.json"))))
    return cases


# ------------------------------------------------------------------------------------- running
def _env(work: Path, extra: dict | None = None) -> dict:
    env = dict(os.environ, MPLBACKEND="Agg", PYVISTA_OFF_SCREEN="true", PYTHONPATH=str(REPO),
               TORQUEBENCH_CACHE=str(SHARED_CACHE))
    env.pop("TORQUEBENCH_DEBUG", None)
    env.update(extra or {})
    return env


def snapshot(root: Path) -> dict:
    """{relative path: ('l', target) | ('f', sha256) | ('d',) | ('o', mode)} of everything under root."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = str(p.relative_to(root))
            if rel.startswith("shared-cache"):
                continue
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                out[rel] = ("l", os.readlink(p))
            elif stat.S_ISREG(st.st_mode):
                h = hashlib.sha256()
                with open(p, "rb") as f:
                    if st.st_size > (64 << 20):
                        h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
                    else:
                        h.update(f.read())
                out[rel] = ("f", h.hexdigest(), st.st_ino)
            elif stat.S_ISDIR(st.st_mode):
                out[rel] = ("d",)
            else:
                out[rel] = ("o", st.st_mode, st.st_rdev)
    return out


def rss_of_group(pgid: int) -> int:
    total = 0
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                parts = f.read().rsplit(")", 1)[1].split()
            if int(parts[2]) != pgid:
                continue
            total += int(parts[21]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, IndexError, ValueError):
            continue
    return total


def run_case(case: Case, base: Path, fixture: Path, timeout: float, max_rss: float, index: int) -> dict:
    croot = base / f"case{index:04d}"
    work = croot / "a" / "b" / "work"
    work.parent.mkdir(parents=True)
    shutil.copytree(fixture, work, symlinks=True)
    cwd_before = os.getcwd()
    try:
        if case.setup is not None:
            case.setup(work)
    finally:
        os.chdir(cwd_before)
    before = snapshot(croot)
    env = _env(work, case.env)
    start = time.perf_counter()
    proc = subprocess.Popen([PY, "-m", "torquebench", *case.argv], cwd=work, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    killed = None
    out_chunks = {"out": b"", "err": b""}
    import threading

    def pump(stream, key):
        out_chunks[key] = stream.read()
    ts = [threading.Thread(target=pump, args=(proc.stdout, "out")),
          threading.Thread(target=pump, args=(proc.stderr, "err"))]
    for t in ts:
        t.start()
    sent_int = False
    late = case.env.get("HOSTILE_LATE_FILE")
    late_done = False
    while proc.poll() is None:
        el = time.perf_counter() - start
        if late and not late_done and el > 1.0:
            (work / late).write_text("the user's file, written during the run\n")
            before[str((work / late).relative_to(croot))] = snapshot(croot).get(str((work / late).relative_to(croot)))
            late_done = True
        if case.sigint_after is not None and not sent_int and el > case.sigint_after:
            os.killpg(proc.pid, signal.SIGINT)
            sent_int = True
        if el > timeout:
            killed = "timeout"
        elif rss_of_group(proc.pid) > max_rss:
            killed = "memory"
        if killed:
            os.killpg(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    for t in ts:
        t.join()
    elapsed = time.perf_counter() - start
    try:
        os.killpg(proc.pid, signal.SIGKILL)          # stray workers of the group
    except ProcessLookupError:
        pass
    after = snapshot(croot)
    rec = {"class": case.cls, "name": case.name, "argv": case.argv, "expect": case.expect,
           "exit": proc.returncode, "time_s": round(elapsed, 2), "killed": killed,
           "stdout": out_chunks["out"].decode("utf-8", "replace")[-3000:],
           "stderr": out_chunks["err"].decode("utf-8", "replace")[-3000:]}
    rec["changed"] = changes(before, after, case, work, croot)
    rec["outcome"] = classify(rec, case, work)
    shutil.rmtree(croot, ignore_errors=True)
    return rec


def changes(before, after, case, work, croot) -> list[str]:
    """Files that existed and changed/vanished (not allowed), and files outside the work dir."""
    wrel = str(work.relative_to(croot))
    bad = []
    allowed = {os.path.normpath(os.path.join(wrel, a)) for a in case.outputs}
    for rel, was in before.items():
        now = after.get(rel)
        if was is None or was[0] == "d":
            continue
        if now is None or now[:2] != was[:2]:
            if rel in allowed:          # a file the case names as replaceable (with --force)
                continue
            bad.append(f"{'removed' if now is None else 'changed'}: {rel}")
    for rel in after:
        if rel not in before and not (rel == wrel or rel.startswith(wrel + os.sep)):
            bad.append(f"created outside the work dir: {rel}")
    return bad


def classify(rec, case, work) -> str:
    err = rec["stderr"]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    code = rec["exit"]
    if rec["killed"]:
        # a run the user asked to be long is fine once its estimated cost was shown first
        if case.expect == "cost" and "estimated" in err.lower() and rec["killed"] == "timeout":
            return "ok"
        return "runaway"
    if "Traceback (most recent call last)" in err or "internal error" in err or code == 1 or \
            (code is not None and code < 0 and case.expect != "interrupt"):
        return "traceback"
    if rec["changed"]:
        return "data_loss"
    if case.expect == "interrupt":
        if code == 130 and len(lines) <= 1:
            return "ok"
        if code == 0:
            return "ok"                 # finished before the signal
        return "unclear"
    if code == 2 and len(lines) != 1:
        return "unclear"
    if code == 2 and "not found" in err.lower() and any((work / a).exists() for a in case.argv if isinstance(a, str)
                                                         and not a.startswith("-") and "/" not in a):
        return "unclear"
    text = (rec["stdout"] + err).lower()
    if case.expect == "ok":
        return "ok" if code == 0 else "refused_valid"
    if case.expect in ("refuse", "error") and code == 0 and "warning" not in text:
        return "silent"
    if case.expect == "cost" and code == 0 and "estimated" not in text:
        return "silent"
    return "ok"


# ------------------------------------------------------------------------------------- mounts
def mount_fs(base: Path) -> dict:
    mounts = {}
    if os.geteuid() != 0:
        return mounts
    ro, full = base / "rofs", base / "fullfs"
    ro.mkdir()
    full.mkdir()
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(ro)], check=True,
                       capture_output=True)
        (ro / "cache").mkdir()
        subprocess.run(["mount", "-o", "remount,ro", str(ro)], check=True, capture_output=True)
        mounts["rofs"] = str(ro)
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(full)], check=True,
                       capture_output=True)
        (full / "cache").mkdir()
        (full / "demo").mkdir()
        try:
            with open(full / "filler", "wb") as f:
                while True:
                    f.write(b"\0" * 4096)
                    f.flush()
        except OSError:
            pass
        mounts["fullfs"] = str(full)
    except (subprocess.CalledProcessError, FileNotFoundError):
        pass
    return mounts


def unmount(mounts):
    for d in mounts.values():
        subprocess.run(["umount", d], capture_output=True)


# ------------------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", action="append", default=None)
    ap.add_argument("--limit", type=int, default=None, help="at most N cases per class")
    ap.add_argument("--match", action="append", default=None, help="only cases whose name contains this text (repeatable: any)")
    ap.add_argument("--timeout", type=float, default=90.0)
    ap.add_argument("--max-rss-gb", type=float, default=4.0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--repo", type=Path, default=None,
                    help="the checkout to test (default: this one), e.g. an exported older commit")
    args = ap.parse_args(argv)
    global REPO, SHARED_CACHE
    if args.repo is not None:
        REPO = args.repo.resolve()
    sys.path.insert(0, str(REPO))
    rng = random.Random(args.seed)
    base = Path(tempfile.mkdtemp(prefix="hostile_pass_"))
    mounts = mount_fs(base)
    try:
        fixture = build_fixture(base)
        cases = (gen_paths(rng) + gen_nonsense(rng) + gen_oserror(rng, mounts) + gen_runaway(rng)
                 + gen_interrupt(rng) + gen_valid(rng) + gen_identify_and_3d(rng))
        cases = [c for c in cases if not c.needs or c.needs in mounts]
        if args.only:
            cases = [c for c in cases if c.cls in args.only]
        if args.match:
            cases = [c for c in cases if any(m in c.name for m in args.match)]
        if args.limit:
            per = {}
            keep = []
            for c in cases:
                per[c.cls] = per.get(c.cls, 0) + 1
                if per[c.cls] <= args.limit:
                    keep.append(c)
            cases = keep
        if args.list:
            for c in cases:
                print(c.cls, "|", c.name, "|", " ".join(c.argv))
            return 0
        print(f"hostile pass: {len(cases)} cases (seed {args.seed}, {args.jobs} jobs) in {base}", file=sys.stderr)
        SHARED_CACHE = base / "shared-cache"
        SHARED_CACHE.mkdir(exist_ok=True)
        records = []
        t0 = time.perf_counter()
        with ThreadPoolExecutor(args.jobs) as pool:
            futs = [pool.submit(run_case, c, base, fixture, args.timeout, args.max_rss_gb * 2 ** 30, i)
                    for i, c in enumerate(cases)]
            for i, f in enumerate(futs):
                r = f.result()
                records.append(r)
                if r["outcome"] != "ok":
                    print(f"[{i + 1}/{len(cases)}] {r['outcome']:>14s}  {r['class']:>9s}  {r['name']}  "
                          f"(exit {r['exit']}, {r['time_s']} s) {r['changed'][:2]} "
                          f"{(r['stderr'].strip().splitlines() or [''])[-1][:160]}", file=sys.stderr)
        total = time.perf_counter() - t0
    finally:
        unmount(mounts)
        if args.list:
            shutil.rmtree(base, ignore_errors=True)
    table = {}
    for r in records:
        table.setdefault(r["class"], {}).setdefault(r["outcome"], 0)
        table[r["class"]][r["outcome"]] += 1
    outcomes = ["ok", "silent", "data_loss", "traceback", "runaway", "unclear", "refused_valid"]
    print(f"{'class':10s} {'cases':>6s} " + " ".join(f"{o:>13s}" for o in outcomes))
    for cls, row in table.items():
        print(f"{cls:10s} {sum(row.values()):6d} " + " ".join(f"{row.get(o, 0):13d}" for o in outcomes))
    allrows = {o: sum(row.get(o, 0) for row in table.values()) for o in outcomes}
    print(f"{'total':10s} {len(records):6d} " + " ".join(f"{allrows[o]:13d}" for o in outcomes))
    print(f"wall time {total:.0f} s (load: shared machine)")
    if args.json:
        args.json.write_text(json.dumps({"seed": args.seed, "table": table, "records": records}, indent=1))
    shutil.rmtree(base, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
