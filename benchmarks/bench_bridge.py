"""Sensor-chain throughput (samples/s) against numpy's rng.normal on the same size, same run.

    python benchmarks/bench_bridge.py [--n 10000000] [--repeat 5]

Prints, for the paper's chain (full bridge, exactly linear) and a quarter bridge (non-linear
closed form + exact inverse): best-of-repeat samples/s of ``counts`` and ``measure``, and the
ratio to ``rng.normal(size=n)`` (the anchor: one Gaussian draw per sample is the floor of any
noisy chain). Target: ≥ 1e7 samples/s.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _best(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> dict:
    from bridge.chain import paper_chain

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    n = args.n
    rng = np.random.default_rng(0)
    tau = rng.uniform(-2.0, 2.0, n)
    t_anchor = _best(lambda: rng.normal(size=n), args.repeat)
    out = {"n": n, "anchor_rng_normal_samples_per_s": n / t_anchor}
    for name, chain in (("paper_full_bridge", paper_chain()),
                        ("quarter_bridge", paper_chain(arrangement="quarter"))):
        for method in ("counts", "measure"):
            fn = getattr(chain, method)
            t = _best(lambda: fn(tau, rng), args.repeat)
            out[f"{name}_{method}_samples_per_s"] = n / t
            out[f"{name}_{method}_time_vs_anchor"] = t / t_anchor
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"n = {n:,} samples, best of {args.repeat}")
        print(f"anchor rng.normal(size=n): {out['anchor_rng_normal_samples_per_s']:.3g} samples/s")
        for key, v in out.items():
            if key.endswith("_samples_per_s") and not key.startswith("anchor"):
                stem = key.removesuffix("_samples_per_s")
                ok = "meets" if v >= 1e7 else "MISSES"
                print(f"{stem:<32} {v:.3g} samples/s  ({out[stem + '_time_vs_anchor']:.2f}× the "
                      f"anchor's time; {ok} the 1e7/s target)")
    return out


if __name__ == "__main__":
    main()
