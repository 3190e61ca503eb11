"""Huge headers, files and devices; huge sizes (walkers, rows, n_avg, thin walls, gains).
"""

from __future__ import annotations

from pathlib import Path

from hostile_cases.common import Case, text_edit


def _big_session(n):
    def setup(w: Path):
        import numpy as np

        rng = np.random.default_rng(0)
        m = np.tile([10, 20, 50, 100, 200, 500, 1000], n // 7 + 1)[:n]
        r = 5.0 + 0.0115 * m + rng.normal(0, 0.01, n)
        (w / "big.csv").write_text("# reading_unit=mV\nmass_g,reading,lever_arm_m\n"
                                   + "\n".join(f"{a},{b:.6f},0.205" for a, b in zip(m, r)) + "\n")
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
                          text_edit("e2e.toml", "cal_scene.toml",
                                     lambda s, n=n_avg: s + f"\n[calibration]\nn_avg = {n}\n"), "error"))
    for kp in ("1e12", "1e9", "1e15"):
        cases.append(Case("runaway", f"simulate kp {kp}", ["simulate", "scene.toml", "--out", "o.csv"],
                          text_edit("scene.toml", "scene.toml", lambda s, kp=kp: s.replace("kp = 500.0", f"kp = {kp}")),
                          "error"))
    for edit in (("thickness_mm = 2.2", "thickness_mm = 0.2"), ("spoke_width_mm = 3.5", "spoke_width_mm = 0.05"),
                 ('preset = "6061-T6"', 'preset = "6061-T6"\nnu = 0.4999'),
                 ('preset = "6061-T6"', 'preset = "6061-T6"\nnu = 0.49999'),
                 ("outer_radius_mm = 30.0", "outer_radius_mm = 3000.0")):
        cases.append(Case("runaway", f"flexure {edit[1].splitlines()[-1]}", ["flexure", "d2.toml"],
                          text_edit("design.toml", "d2.toml", lambda s, e=edit: s.replace(*e)), "error"))
    cases.append(Case("runaway", "sweep 1000 points (cost shown first)",
                      ["sweep", "e2e.toml", "--vary", "sensors.seed=" + ",".join(map(str, range(1000))),
                       "--executor", "local"], None, "cost"))
    cases.append(Case("runaway", "compare 400 points (cost shown first)",
                      ["compare", "e2e.toml", "--vary", "sensors.seed=" + ",".join(map(str, range(400)))], None, "cost"))
    cases.append(Case("runaway", "flexure sweep 1000 designs",
                      ["flexure", "--sweep", "spoke_width_mm=" + ",".join(f"{3 + i * 1e-3:.3f}" for i in range(1000))],
                      None, "cost"))
    return cases
