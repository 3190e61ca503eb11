"""Ctrl-C (SIGINT) part-way through long commands.
"""

from __future__ import annotations


from hostile_cases.common import Case


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
