"""Identification speed: ``torquebench identify`` on 20 s of a 1 kHz excitation log (target ≤ 2 s
on one core), in process after a warm-up, anchored by ``pandas.read_csv`` of the same log and by
``torquebench estimate`` on it, measured in the same run (the machine may be shared: compare
ratios). The log: the shipped excitation scene's reference realized by inverse dynamics of a
perturbed paper leg, with the paper leg's sensor noise.

Run: ``python benchmarks/bench_identify.py [--seconds 20] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")          # one core, as the target is stated

import numpy as np  # noqa: E402


def _best(fn, repeat):
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    return best


def make_log(path, seconds: float):
    from estimator import inertial
    from estimator.excitation import Fourier
    from estimator.log import SensorLog
    from estimator.model import ModelUncertainty
    from estimator.noise import NoiseModel
    from estimator.robot import paper_leg
    from estimator.sim.output import log_files
    from estimator.synthetic import inverse_dynamics_log
    from torquebench.scenes import load_scene, scene_path
    from userio.files import write_files_atomic

    true = inertial.perturbed(paper_leg(), ModelUncertainty(0.05, 0.1, 0.003), 1)
    ctrl = load_scene(scene_path("identification_excitation")).sim.controller
    t = np.arange(int(seconds * 1000) + 1) / 1000.0
    qj, dqj, ddqj = Fourier.from_controller(ctrl).evaluate(t)
    z = np.zeros((len(t), 3))
    q, dq, ddq = (np.concatenate([z, x], axis=1) for x in (qj, dqj, ddqj))
    log, _ = inverse_dynamics_log(true, t, q, dq, ddq, 1, 0.5, [0, 0], active=np.zeros(len(t), bool))
    e = np.random.default_rng(0).standard_normal((len(t), 5)) * [0.1, 0.1, 0.01, 0.005, 0.005]
    log = SensorLog(t=t, q=q, dq=dq, tau_Nm=log.tau_Nm + e[:, 3:], wrench=log.wrench + e[:, :3])
    T = len(t)
    truth = {"t": t, "link": np.zeros(T, int), **{k: np.full(T, np.nan) for k in
                                                   ("alpha", "Fx", "Fz", "px", "pz")}}
    write_files_atomic(log_files(path, log, truth, path.with_name("exc.truth.csv"),
                                 NoiseModel([0.005], [0.1, 0.1, 0.01])))


def main(argv=None) -> dict:
    import contextlib
    import io
    import tempfile
    from pathlib import Path

    import pandas as pd

    from torquebench.cli import main as cli

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_identify_") as tmp:
        log = Path(tmp) / "exc.csv"
        make_log(log, args.seconds)
        out = Path(tmp) / "id.toml"

        def identify():
            with contextlib.redirect_stdout(io.StringIO()):
                assert cli(["identify", str(log), "--out", str(out), "--force", "--json"]) == 0

        def estimate():
            with contextlib.redirect_stdout(io.StringIO()):
                assert cli(["estimate", str(log), "--json"]) == 0

        identify()                                   # warm-up: imports, numba's cache
        estimate()
        wall, cpu = _best(identify, args.repeat)
        read, _ = _best(lambda: pd.read_csv(log, dtype=float), args.repeat)
        est, _ = _best(estimate, args.repeat)
    res = {"seconds_of_log": args.seconds, "samples": int(args.seconds * 1000) + 1,
           "identify_s": wall, "identify_cpu_s": cpu, "anchor_pandas_read_csv_s": read,
           "anchor_estimate_s": est, "ratio_identify_to_read_csv": wall / read,
           "ratio_identify_to_estimate": wall / est}
    print(f"torquebench identify on {args.seconds:g} s at 1 kHz: {wall:.2f} s wall, CPU {cpu:.2f} s "
          f"(target <= 2 s on one core, in process after a warm-up)")
    print(f"  anchors in the same run: pandas.read_csv of the log {read:.3f} s "
          f"(identify = {wall / read:.1f}x), torquebench estimate on it {est:.2f} s "
          f"(identify = {wall / est:.2f}x)")
    return res


if __name__ == "__main__":
    main()
