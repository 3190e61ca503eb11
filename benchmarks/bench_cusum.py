"""CUSUM threshold calibration (estimator.cusum_calibration.calibrate): its cost, and the cost of a direct
Monte Carlo that would measure the alarm rate at one false alarm per hour (1 kHz) to the same
relative error, anchored by timing the same synthetic residual and detector on 1e6 samples.

Run: ``python benchmarks/bench_cusum.py``. Prints figures and ratios measured in the same run
(the machine may be shared: compare ratios). Direct Monte Carlo at rate α to relative error ε
needs T = 1/(α ε²) samples (Poisson count); its time is T times the per-sample time of the anchor.
"""

from __future__ import annotations

import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")          # one core

import numpy as np  # noqa: E402


def main() -> None:
    from estimator import cusum_calibration as C
    from estimator import noise as Nz
    from estimator import sequential as S
    from estimator.robot import paper_leg

    robot = paper_leg()
    q0 = np.array([0.0, 0.0, 0.0, 0.9, -1.6])
    tim = [("mean", 0.0)] * 5
    a, b, B0, B1 = Nz.filter_terms(robot, q0, 0 * q0, Nz.paper_leg_noise(), 100.0, 1e-3, tim)
    R = Nz.residual_covariance(robot, q0, 0 * q0, Nz.paper_leg_noise(), 100.0, 1e-3, tim)[0]
    model = (a, b, B0[0], B1[0], R)
    C.calibrate(model, 5, samples=100_000, particles=800, rate_floor=1e-4)   # compile / load numba
    t0, c0 = time.perf_counter(), time.process_time()
    cal = C.calibrate(model, 5)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    alpha = 1e-3 / 3600
    h = cal.threshold(alpha)
    eps = cal.rate_rel_error(h)
    t0 = time.perf_counter()
    s = C.synthetic_statistic(*model, 1_000_000, seed=1)
    S.cusum(s, 5, h, cal.drift)
    per_sample = (time.perf_counter() - t0) / 1e6
    T_direct = 1.0 / (alpha * eps ** 2)
    print(f"calibration: {wall:.2f} s wall, {cpu:.2f} s CPU ({cal.method})")
    print(f"threshold at 1/h (1 kHz): h = {h:.1f}, calibration 1σ {100 * eps:.1f} %")
    print(f"anchor: synthetic residual + CUSUM, {per_sample * 1e9:.0f} ns/sample")
    print(f"direct Monte Carlo to the same error: {T_direct:.3g} samples, "
          f"{T_direct * per_sample:.3g} s = {T_direct * per_sample / wall:.3g}× the calibration")


if __name__ == "__main__":
    main()
