"""Pipeline timings: cold/warm demo, --explain, a log-only scene's import cost, sweep throughput
at 1 and 2 workers, and the end-to-end scene by stage. Anchor: `python -c "import numpy"` in the
same run (interpreter + numpy start-up); every figure is also printed as a ratio to it.

    .venv/bin/python benchmarks/bench_pipeline.py [--skip-e2e] [--sweep-only]

The sweep (4 seeds of paper_floating_link2, localization_error) runs its first point alone, which
computes the stages every point shares (the simulation) and imports what a point needs, before
fanning out; a parallel anchor (CPU-bound pure-Python tasks on 1 and 2 processes) shows the
speed-up the machine can give at that moment.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def timed(cmd, env=None) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"{' '.join(cmd)} failed: {r.stderr.strip().splitlines()[-1:]}")
    return time.perf_counter() - t0


def _spin(n: int) -> int:
    s = 0
    for i in range(n):
        s += i
    return s


def parallel_anchor(workers: int, tasks: int = 4, n: int = 3_000_000) -> float:
    """Wall time of ``tasks`` CPU-bound pure-Python tasks on a pool of ``workers`` processes: the
    speed-up the machine can give a 2-worker sweep at this moment."""
    from concurrent.futures import ProcessPoolExecutor

    t0 = time.perf_counter()
    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(_spin, [n] * tasks))
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-e2e", action="store_true", help="skip the cold end-to-end scene (FEM)")
    ap.add_argument("--sweep-only", action="store_true", help="only the anchor and the sweep throughput")
    a = ap.parse_args()
    py, tb = sys.executable, [sys.executable, "-m", "torquebench"]
    anchor = min(timed([py, "-c", "import numpy"]) for _ in range(3))
    rows = [("anchor: python -c 'import numpy'", anchor)]
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "TORQUEBENCH_CACHE": str(Path(tmp) / "cache")}
        out = str(Path(tmp) / "demo")
        if not a.sweep_only:
            rows.append(("demo, cold cache", timed(tb + ["demo", "--out-dir", out], env)))
            rows.append(("demo, warm cache", min(timed(tb + ["demo", "--out-dir", out], env) for _ in range(2))))
            rows.append(("run end_to_end --explain", timed(tb + ["run", "scenes/end_to_end.toml", "--explain"], env)))
            code = ("import time; t=time.perf_counter(); import torquebench.pipeline, torquebench.scenes, "
                    "estimator.estimate, calibration.model; print(time.perf_counter()-t)")
            r = subprocess.run([py, "-c", code], cwd=ROOT, capture_output=True, text=True)
            rows.append(("imports of a log-only scene (in process)", float(r.stdout.strip())))
        par = {w: parallel_anchor(w) for w in (1, 2)}
        sweep, sim_runs = {}, {}
        for w in (1, 2):
            env_w = {**os.environ, "TORQUEBENCH_CACHE": str(Path(tmp) / f"sweep{w}")}
            t0 = time.perf_counter()
            r = subprocess.run(tb + ["sweep", "scenes/paper_floating_link2.toml", "--vary",
                                     "sensors.seed=1,2,3,4", "--executor", f"processes:{w}", "--only",
                                     "localization_error", "--json"], cwd=ROOT, env=env_w,
                               capture_output=True, text=True)
            sweep[w] = time.perf_counter() - t0
            doc = json.loads(r.stdout)
            sim_runs[w] = sum(p.get("stages", {}).get("simulation") == "run" for p in doc["points"])
            rows.append((f"sweep 4 points, processes:{w} ({4 / sweep[w]:.2f} points/s)", sweep[w]))
        stages = []
        if not (a.skip_e2e or a.sweep_only):
            env_e = {**os.environ, "TORQUEBENCH_CACHE": str(Path(tmp) / "e2e")}
            t0 = time.perf_counter()
            r = subprocess.run(tb + ["run", "scenes/end_to_end.toml", "--json"], cwd=ROOT, env=env_e,
                               capture_output=True, text=True)
            rows.append(("end_to_end scene, cold", time.perf_counter() - t0))
            stages = json.loads(r.stdout)["stages"]
    for name, t in rows:
        print(f"{name:52s} {t:8.2f} s  {t / anchor:8.1f} × anchor")
    for s in stages:
        print(f"  end_to_end stage {s['stage']:22s} {s['time_s']:8.2f} s")
    if 1 in par:
        print(f"parallel anchor (4 CPU-bound pure-Python tasks): processes:2 is {par[1] / par[2]:.2f}× "
              f"as fast as processes:1 ({par[1]:.2f} s vs {par[2]:.2f} s): the parallelism this machine "
              f"gives now")
        print(f"sweep: processes:2 is {sweep[1] / sweep[2]:.2f}× as fast as processes:1; the shared "
              f"simulation ran {sim_runs[1]}× (1 worker) and {sim_runs[2]}× (2 workers)")
    print("(2-core machine shared with other jobs: timings are noisy)")


if __name__ == "__main__":
    main()
