"""Controls: ordinary inputs that must still work (exit 0).
"""

from __future__ import annotations

import subprocess

from hostile_cases import common
from hostile_cases.common import Case
from hostile_cases.runner import case_env


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
                      lambda w: subprocess.run([common.PY, "-m", "torquebench", "demo", "--out-dir", "d2"], cwd=w,
                                               capture_output=True, env=case_env(w)), "ok",
                      outputs=tuple(f"d2/{n}" for n in ("log.csv", "log.truth.csv", "estimate_dynamic.csv",
                                                        "estimate_paper.csv", ".torquebench-outputs.json"))))
    return cases
