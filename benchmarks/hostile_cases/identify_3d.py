"""Hostile inputs of `identify` and of the URDF (3-D) estimator.
"""

from __future__ import annotations


from hostile_cases.common import Case, alias, csv_edit, scale_cols


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
                      csv_edit("excite.csv", "bad.csv", scale_cols(["tau1", "tau2"], k)), "refuse"))
    cases.append(Case("nonsense", "identify on 40 samples", ["identify", "short.csv", "--robot", "robot.toml"],
                      csv_edit("excite.csv", "short.csv", lambda d: d.iloc[:40]), "refuse"))
    cases.append(Case("nonsense", "identify on a poke log", ["identify", "float.csv", "--robot", "robot.toml"],
                      None, "refuse"))
    cases.append(Case("nonsense", "identify angles in degrees", ["identify", "deg.csv", "--robot", "robot.toml"],
                      csv_edit("excite.csv", "deg.csv", scale_cols(["q1", "q2", "dq1", "dq2"], 57.29578)),
                      "refuse"))
    cases.append(Case("nonsense", "estimate 3-D torques ×1000", ["estimate", "bad3.csv", "--robot", "quad.toml"],
                      csv_edit("leg3d.csv", "bad3.csv", lambda d: d.assign(**{c: d[c] * 1000 for c in d.columns
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
