"""Benchmark: emcee calibration fit of a 10-level × 5-repeat session to convergence.

Targets: < 2 s on one core; posterior mean and std within 2 % of the exact Student-t
posterior. "Mean within 2 %" is measured as |mean_emcee − mean_exact| / std_exact (the relative
error of the mean itself is ~1e-5 and says nothing); std as |std_emcee/std_exact − 1|.
Anchor, measured in the same run: the closed-form exact posterior (QR least squares).
Also: frame-parser throughput (vectorized CRC over candidates) against the stream it must keep up
with (3–4 kSps; anchor: 4000 frames/s), on a stream with 1 % corrupted frames and garbage.
Run: python benchmarks/bench_calibration.py [--seeds 5]
"""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    import emcee  # noqa: F401  (import cost not timed)

    from calibration.fit import fit_session
    from calibration.posterior import design_matrix, exact_posterior
    from calibration.simulate import paper_session

    session = paper_session(1)                      # 10 levels × 5 repeats = 50 readings
    assert len(session) == 50
    t0 = time.perf_counter()
    for _ in range(100):
        ex = exact_posterior(design_matrix(session.mass_g, "linear"), session.reading)
    t_exact = (time.perf_counter() - t0) / 100
    fit_session(session, seed=99)                   # warm-up (first-call overheads)
    print(f"session: {len(session)} readings (10 levels × 5 repeats), simulated paper link 1")
    print(f"anchor: exact posterior (closed form) {t_exact * 1e6:.0f} µs")
    print(f"{'moves':8s} {'seed':>4s} {'time_s':>7s} {'tau':>6s} {'steps':>6s} {'acc':>5s} "
          f"{'mean_err_slope':>15s} {'mean_err_offset':>16s} {'std_err_slope':>14s} {'std_err_offset':>15s}")
    rows = {}
    for moves in ("de", "stretch"):
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            fit = fit_session(session, seed=seed, moves=moves)
            dt = time.perf_counter() - t0
            me = np.abs(fit.mean[:2] - ex.beta) / ex.std
            se = np.abs(fit.std[:2] / ex.std - 1)
            rows.setdefault(moves, []).append((dt, fit.tau_max, me.max(), se.max(), fit.converged))
            print(f"{moves:8s} {seed:4d} {dt:7.3f} {fit.tau_max:6.1f} {fit.n_steps:6d} "
                  f"{fit.acceptance_fraction:5.2f} {me[0]:15.2%} {me[1]:16.2%} {se[0]:14.2%} {se[1]:15.2%}")
    for moves, r in rows.items():
        r = np.array(r, float)
        print(f"{moves}: median time {np.median(r[:, 0]):.3f} s (= {np.median(r[:, 0]) / t_exact:.0f}× "
              f"the closed form), τ {np.median(r[:, 1]):.1f}, max mean error {r[:, 2].max():.2%} of σ, "
              f"max std error {r[:, 3].max():.2%}, converged {int(r[:, 4].sum())}/{len(r)}; "
              f"targets < 2 s: {'met' if np.median(r[:, 0]) < 2 else 'MISSED'}, ≤ 2 %: "
              f"{'met' if max(r[:, 2].max(), r[:, 3].max()) <= 0.02 else 'MISSED'}")

    parser_throughput()


def parser_throughput(n_frames: int = 200_000, n_ch: int = 2, chunk: int = 4096):
    """Frames parsed per second, fed in ``chunk``-byte reads like the serial port gives them."""
    from calibration.frames import FrameParser, encode_frames, frame_length

    rng = np.random.default_rng(0)
    data = bytearray(encode_frames(np.arange(n_frames), rng.integers(-2**23, 2**23, (n_frames, n_ch))))
    L = frame_length(n_ch)
    bad = rng.choice(n_frames, n_frames // 100, replace=False)
    for k in bad:                                   # 1 % corrupted frames
        data[k * L + 6] ^= 0x5A
    data = bytes(data)
    p = FrameParser(n_ch)
    t0 = time.perf_counter()
    for i in range(0, len(data), chunk):
        p.feed(data[i:i + chunk])
    dt = time.perf_counter() - t0
    rate = p.stats.frames / dt
    print(f"parser: {p.stats.frames} frames ({p.stats.corrupted} corrupted, {p.stats.lost} lost) in "
          f"{dt:.2f} s = {rate:,.0f} frames/s = {rate / 4000:.0f}× the 4 kSps stream "
          f"({len(data) / dt / 1e6:.1f} MB/s; 2 Mbaud carries 0.2 MB/s)")


if __name__ == "__main__":
    main()
