"""Read-only or full file systems (small tmpfs mounts when the process may mount), device or
directory inputs, unresolvable hosts, hash-valid files with wrong types.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import subprocess
import sys
from pathlib import Path

from hostile_cases import common
from hostile_cases.common import Case, csv_edit_commented, text_edit


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

        sys.path.insert(0, str(common.REPO))
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
                          csv_edit_commented("session.csv", "s2.csv", fn), "any"))
    # extreme numbers that overflow
    for argv in (["estimate", "fixed.csv", "--timing", "delay:1e300"],
                 ["estimate", "fixed.csv", "--torque-sigma", "1e-300"],
                 ["estimate", "fixed.csv", "--ft-sigma", "1e-300,1e-300,1e-300"],
                 ["run", "scene.toml", "--seed", "-1"],
                 ["flexure", "d2.toml", "--single-level"]):
        setup = text_edit("design.toml", "d2.toml", lambda s: s.replace("thickness_mm = 2.2", "thickness_mm = 1e300")) \
            if argv[0] == "flexure" else None
        cases.append(Case("oserror", " ".join(argv)[:60], argv, setup, "error"))
    return cases


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
