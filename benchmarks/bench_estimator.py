"""Estimator speed: offline observer + dynamic localization, streaming step latency, and our
batched M, C, G against looped pinocchio on the same states.

Run: ``python benchmarks/bench_estimator.py [--samples 1000000] [--end-to-end 2000000]
[--ten-million]``. Prints figures and ratios against anchors measured in the same run (the machine
may be shared: compare ratios).

End to end (``bench_end_to_end``): a 2-link floating-base log of the paper leg swinging with a
few pokes and the paper leg's sensor noise, written once (CSV with 9 significant digits, and
Parquet) to a temporary directory; ``torquebench estimate LOG --out OUT`` timed in process
(reading, estimating, writing; CSV -> CSV, Parquet -> Parquet, CSV -> Parquet, CSV without --out;
wall and CPU seconds), anchored by the bare readers of the same CSV (``pandas.read_csv``,
``pyarrow.csv.read_csv``); the same command in a fresh process with its peak resident memory
(VmHWM). ``--ten-million`` adds a 10 M-sample log (the 2 M-sample log five times over). On a
shared machine the wall figures are pessimistic: samples per CPU-second are printed too.
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")          # one core, as the targets are stated

import numpy as np  # noqa: E402

CPU = {}


def _best(fn, repeat=3, key=None):
    """Best wall time of ``repeat`` runs; the CPU time of that run is kept in CPU[key]."""
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    if key:
        CPU[key] = best[1]
    return best[0]


def bench_offline(n_samples: int, repeat: int = 3) -> dict:
    from scipy.signal import lfilter

    from estimator import localization as L
    from estimator import observer as O
    from estimator.estimate import estimate
    from estimator.robot import paper_leg
    from estimator.synthetic import moving_leg_poke

    robot = paper_leg()
    t0 = time.perf_counter()
    log, truth = moving_leg_poke(robot, duration_s=n_samples / 1000.0, t_on_s=0.0,
                                 frequency_Hz=1.0, base_amplitude=(0.01, 0.01, 0.05))
    gen = time.perf_counter() - t0
    estimate(robot, log, method="dynamic")                        # warm-up (imports, caches)
    stages = {}
    terms = {}

    def observer_only():
        terms["r"] = O.residual_offline(robot, log.t, log.q, log.dq, log.tau_meas, 100.0)

    stages["observer_s"] = _best(observer_only, repeat)
    stages["localize_dynamic_s"] = _best(lambda: L.localize_dynamic(robot, log.q, terms["r"]), repeat)
    result = {}

    def full():
        result["est"] = estimate(robot, log, method="dynamic")

    stages["estimate_dynamic_s"] = _best(full, repeat, key="estimate")
    from estimator.model import ModelUncertainty

    declared = ModelUncertainty(0.05, 0.10, 0.003)
    estimate(robot, log, model_uncertainty=declared)              # warm-up of the model term
    stages["estimate_model_s"] = _best(lambda: estimate(robot, log, model_uncertainty=declared),
                                       repeat, key="estimate_model")
    stages["estimate_dynamic_again_s"] = _best(full, repeat, key="estimate_again")
    from estimator import compiled

    compiled.ENABLED = False                 # before: the numpy forms (same run, same log)
    try:
        stages["estimate_numpy_forms_s"] = _best(full, repeat, key="estimate_numpy")
    finally:
        compiled.ENABLED = True

    def detector_only():                  # whitening + chi-square threshold on the residual
        from estimator import noise as Nz
        R = Nz.residual_covariance(robot, log.q[:1], log.dq[:1], Nz.paper_leg_noise(), 100.0, 1e-3)[0]
        from estimator.detection import chi2_isf, whitened_sumsq
        Linv = np.linalg.inv(np.linalg.cholesky(R))
        whitened_sumsq(np.ascontiguousarray(terms["r"].T), Linv) > chi2_isf(1e-3 / 3600, 5)

    stages["detector_s"] = _best(detector_only, repeat)
    est = result["est"]
    settled = log.t > 0.05
    err = np.hypot(est.px - truth.point_m[:, 0], est.pz - truth.point_m[:, 1])[settled]
    # anchor: one memory pass of the same size (lfilter of 5 channels over the log)
    x = np.ascontiguousarray(log.tau_meas.T)
    anchor = _best(lambda: [lfilter([0.1], [1.0, -0.9], x[j]) for j in range(5)], repeat)
    return {"samples": n_samples, "log_generation_s": gen, **stages,
            "samples_per_s": n_samples / stages["estimate_dynamic_s"],
            "samples_per_cpu_s": n_samples / CPU["estimate"],
            "numpy_forms_samples_per_s": n_samples / stages["estimate_numpy_forms_s"],
            "numpy_forms_samples_per_cpu_s": n_samples / CPU["estimate_numpy"],
            "ratio_numpy_forms_over_compiled": stages["estimate_numpy_forms_s"] / stages["estimate_dynamic_s"],
            "model_term_us_per_sample": 1e6 * (stages["estimate_model_s"] - min(
                stages["estimate_dynamic_s"], stages["estimate_dynamic_again_s"])) / n_samples,
            "model_term_cpu_us_per_sample": 1e6 * (CPU["estimate_model"] - min(
                CPU["estimate"], CPU["estimate_again"])) / n_samples,
            "ratio_model_over_plain": stages["estimate_model_s"] / min(
                stages["estimate_dynamic_s"], stages["estimate_dynamic_again_s"]),
            "compiled_kernels": compiled.available(),
            "detector_samples_per_s": n_samples / stages["detector_s"],
            "observer_plus_localize_samples_per_s":
                n_samples / (stages["observer_s"] + stages["localize_dynamic_s"]),
            "anchor_lfilter_5ch_s": anchor,
            "ratio_estimate_to_lfilter_anchor": stages["estimate_dynamic_s"] / anchor,
            "position_error_max_m": float(np.nanmax(err)),
            "contact_fraction": float(est.contact[settled].mean())}


def bench_streaming(n_steps: int = 20000) -> dict:
    from estimator.observer import MomentumObserver
    from estimator.robot import paper_leg
    from estimator.synthetic import moving_leg_poke

    robot = paper_leg()
    log, _ = moving_leg_poke(robot, duration_s=n_steps / 1000.0, t_on_s=0.0)
    obs = MomentumObserver(robot, 1e-3, 100.0)
    q, dq, tau = log.q, log.dq, log.tau_meas
    lat = np.empty(n_steps)
    clock = time.perf_counter_ns
    for k in range(n_steps):
        t0 = clock()
        obs.step(q[k], dq[k], tau[k])
        lat[k] = clock() - t0
    # anchor: one 5×5 matrix-vector product through numpy, per call
    M = np.eye(5)
    v = np.ones(5)
    anchor = np.empty(2000)
    for k in range(2000):
        t0 = clock()
        M @ v
        anchor[k] = clock() - t0
    return {"steps": n_steps, "median_us": float(np.median(lat) / 1e3),
            "p99_us": float(np.percentile(lat, 99) / 1e3),
            "anchor_numpy_matvec_median_us": float(np.median(anchor) / 1e3),
            "ratio_step_to_matvec": float(np.median(lat) / np.median(anchor))}


def bench_vs_pinocchio(n_states: int = 20000) -> dict:
    from estimator import dynamics as D
    from estimator.observer import chain_terms
    from estimator.robot import paper_leg

    try:
        import pinocchio as pin
    except ImportError:                      # test extra not installed
        return {"skipped": "pinocchio not installed"}
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_dynamics import pinocchio_model

    robot = paper_leg()
    model = pinocchio_model(robot)
    data = model.createData()
    rng = np.random.default_rng(0)
    q = rng.uniform(-np.pi, np.pi, (n_states, 5))
    dq = rng.normal(0, 2, (n_states, 5))

    def ours_matrices():
        D.mass_matrix(robot, q), D.coriolis_matrix(robot, q, dq), D.gravity_vector(robot, q)

    def ours_terms():
        chain_terms(robot, q, dq, want=("P", "CTdq", "Cdq", "G"))

    def pinocchio_loop():
        for k in range(n_states):
            pin.crba(model, data, q[k])
            pin.computeCoriolisMatrix(model, data, q[k], dq[k])
            pin.computeGeneralizedGravity(model, data, q[k])

    t_ours = _best(ours_matrices)
    t_terms = _best(ours_terms)
    t_pin = _best(pinocchio_loop, 2)
    return {"states": n_states, "ours_batched_MCG_s": t_ours, "ours_chain_terms_s": t_terms,
            "pinocchio_looped_s": t_pin, "ratio_pinocchio_over_ours_MCG": t_pin / t_ours,
            "ratio_pinocchio_over_ours_chain_terms": t_pin / t_terms}


def _write_log_csv(path, blocks):
    """Write log blocks (SensorLog) as one CSV with 9 significant digits (pyarrow)."""
    import pyarrow as pa
    import pyarrow.csv as pc

    from estimator.log import log_columns, log_to_frame
    from estimator.outframe import round_significant

    writer = None
    for log in blocks:
        frame = log_to_frame(log)
        table = pa.table({c: round_significant(frame[c].to_numpy()) for c in frame.columns})
        if writer is None:
            cols = log_columns(log.n_links, log.floating)
            assert list(frame.columns) == cols
            writer = pc.CSVWriter(str(path), table.schema, write_options=pc.WriteOptions(
                quoting_style="none", quoting_header="none"))
        writer.write_table(table)
    writer.close()


def _log_blocks(n_samples: int, period_samples: int = 200_000):
    """The bench log in blocks: 200 s of the leg swinging at 1 Hz with two pokes (link 2, α = 0.5,
    5 N, 3 s and 20 s long), paper-leg sensor noise, repeated (continuous: whole periods)."""
    from estimator.log import SensorLog
    from estimator.robot import paper_leg
    from estimator.synthetic import inverse_dynamics_log, sinusoidal_motion

    robot = paper_leg()
    T = min(period_samples, n_samples)
    t = np.arange(T) / 1000.0
    q, dq, ddq = sinusoidal_motion(robot, t, frequency_Hz=1.0, base_amplitude=(0.01, 0.01, 0.05))
    active = ((t >= 20) & (t < 23)) | ((t >= 120) & (t < 140))
    base, _ = inverse_dynamics_log(robot, t, q, dq, ddq, 2, 0.5,
                                   5.0 * np.array([np.cos(-np.pi / 3), np.sin(-np.pi / 3)]), active=active)
    rng = np.random.default_rng(0)
    done = 0
    while done < n_samples:
        m = min(T, n_samples - done)
        yield SensorLog(t=t[:m] + done / 1000.0, q=q[:m], dq=dq[:m],
                        tau_Nm=base.tau_Nm[:m] + rng.normal(0, 0.005, (m, 2)),
                        wrench=base.wrench[:m] + rng.normal(0, [0.1, 0.1, 0.01], (m, 3)))
        done += m


def _fresh_process(argv) -> tuple[float, float, float]:
    """(wall s, CPU s, peak RSS MB) of ``torquebench ARGV --json`` in a fresh process (its own
    ``peak_memory_MB``: VmHWM, the interpreter and imports included; CPU: user + system of the
    child, all its threads)."""
    import json
    import resource
    import subprocess
    import sys

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "torquebench", *argv, "--json"], capture_output=True,
                          text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, float(json.loads(proc.stdout)["peak_memory_MB"])


def bench_end_to_end(n_samples: int = 2_000_000, ten_million: bool = False) -> dict:
    """``torquebench estimate LOG --out OUT`` on CSV -> CSV, Parquet -> Parquet, CSV -> Parquet and
    CSV without --out, in process after a warm-up (wall and CPU of the whole process, every
    thread), anchored by the bare readers of the same CSV in the same run (pandas.read_csv and
    pyarrow.csv.read_csv, all columns float64); then CSV -> CSV and Parquet -> Parquet in a fresh
    process (imports and all) with their peak resident memory."""
    import contextlib
    import io
    import json
    import tempfile
    from pathlib import Path

    import pandas as pd
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    from estimator.log import log_columns, log_to_frame
    from torquebench.cli import main as cli

    out = {"samples": n_samples}
    with tempfile.TemporaryDirectory(prefix="bench_estimate_") as tmp:
        tmp = Path(tmp)
        csv, parquet = tmp / "log.csv", tmp / "log.parquet"
        t0 = time.perf_counter()
        _write_log_csv(csv, _log_blocks(n_samples))
        writer = None
        for log in _log_blocks(n_samples):
            table = pa.Table.from_pandas(log_to_frame(log), preserve_index=False)
            writer = writer or pq.ParquetWriter(str(parquet), table.schema)
            writer.write_table(table)
        writer.close()
        out["log_writing_s"] = time.perf_counter() - t0
        out["csv_MB"] = csv.stat().st_size / 1e6
        out["anchor_pandas_read_csv_s"] = _best(lambda: pd.read_csv(csv, dtype=float), 1,
                                                key="anchor_pandas")
        out["anchor_pandas_read_csv_cpu_s"] = CPU["anchor_pandas"]
        types = {c: pa.float64() for c in log_columns(2, True)}
        out["anchor_pyarrow_read_csv_s"] = _best(lambda: pcsv.read_csv(
            csv, convert_options=pcsv.ConvertOptions(column_types=types)), 1, key="anchor_arrow")
        out["anchor_pyarrow_read_csv_cpu_s"] = CPU["anchor_arrow"]

        with contextlib.redirect_stdout(io.StringIO()):         # warm-up: imports, caches
            small = tmp / "small.csv"
            _write_log_csv(small, _log_blocks(5000))
            cli(["estimate", str(small), "--out", str(tmp / "warm.csv"), "--force", "--json"])
            cli(["estimate", str(small), "--out", str(tmp / "warm.parquet"), "--force", "--json"])
        for name, src, dst, extra in (
                ("csv", csv, tmp / "est.csv", []), ("parquet", parquet, tmp / "est.parquet", []),
                ("csv_to_parquet", csv, tmp / "est2.parquet", []), ("csv_no_out", csv, None, []),
                ("csv_model", csv, tmp / "est4.csv", ["--model-uncertainty", "0.05"]),
                ("parquet_model", parquet, tmp / "est4.parquet", ["--model-uncertainty", "0.05"])):
            argv = ["estimate", str(src), "--json", *extra] + \
                ([] if dst is None else ["--out", str(dst), "--force"])
            buf = io.StringIO()
            t0, c0 = time.perf_counter(), time.process_time()
            with contextlib.redirect_stdout(buf):
                code = cli(argv)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            assert code == 0
            out[f"{name}_intervals"] = len(json.loads(buf.getvalue())["intervals"])
            out[f"{name}_s"], out[f"{name}_cpu_s"] = wall, cpu
            out[f"{name}_samples_per_s"] = n_samples / wall
            out[f"{name}_samples_per_cpu_s"] = n_samples / cpu
        out["ratio_csv_model_to_csv"] = out["csv_model_s"] / out["csv_s"]
        out["ratio_parquet_model_to_parquet_cpu"] = out["parquet_model_cpu_s"] / out["parquet_cpu_s"]
        out["ratio_csv_model_to_pyarrow_anchor_cpu"] = out["csv_model_cpu_s"] / out["anchor_pyarrow_read_csv_cpu_s"]
        out["load_average_1min"] = os.getloadavg()[0]
        out["ratio_csv_to_pandas_anchor"] = out["csv_s"] / out["anchor_pandas_read_csv_s"]
        out["ratio_csv_to_pyarrow_anchor"] = out["csv_s"] / out["anchor_pyarrow_read_csv_s"]
        for name, src, dst in (("csv", csv, tmp / "est3.csv"), ("parquet", parquet, tmp / "est3.parquet")):
            wall, cpu, rss = _fresh_process(["estimate", str(src), "--out", str(dst), "--force"])
            out[f"{name}_subprocess_s"], out[f"{name}_subprocess_cpu_s"] = wall, cpu
            out[f"{name}_peak_rss_MB"] = rss
        if ten_million:
            big = tmp / "log10m.csv"
            _write_log_csv(big, _log_blocks(10_000_000))
            csv.unlink()
            wall, cpu, rss = _fresh_process(["estimate", str(big), "--out", str(tmp / "est10m.csv"), "--force"])
            out["ten_million_s"], out["ten_million_cpu_s"], out["ten_million_peak_rss_MB"] = wall, cpu, rss
    return out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--end-to-end", type=int, default=2_000_000, metavar="SAMPLES",
                        help="samples of the end-to-end CLI log (0: skip)")
    parser.add_argument("--ten-million", action="store_true",
                        help="also the peak memory of a 10 M-sample log (a few minutes)")
    parser.add_argument("--only", choices=["offline", "end-to-end"], default=None)
    args = parser.parse_args(argv)
    out = {}
    if args.only != "end-to-end":
        out = {"offline": bench_offline(args.samples, args.repeat), "streaming": bench_streaming(),
               "dynamics_vs_pinocchio": bench_vs_pinocchio()}
    if args.end_to_end and args.only != "offline":
        e = out["end_to_end"] = bench_end_to_end(args.end_to_end, args.ten_million)
        n = e["samples"]
        print(f"torquebench estimate LOG --out OUT, {n:,} samples ({e['csv_MB']:.0f} MB CSV, "
              f"9 significant digits), in process (target >= 500,000 samples/s):")
        for key, label in (("csv", "CSV -> CSV"), ("parquet", "Parquet -> Parquet"),
                           ("csv_to_parquet", "CSV -> Parquet"), ("csv_no_out", "CSV, no --out"),
                           ("csv_model", "CSV -> CSV, model term"),
                           ("parquet_model", "Parquet -> Parquet, model term")):
            print(f"  {label:20s} {e[key + '_s']:6.2f} s = {e[key + '_samples_per_s']:>10,.0f} samples/s wall; "
                  f"CPU {e[key + '_cpu_s']:.2f} s = {e[key + '_samples_per_cpu_s']:,.0f} samples per CPU-second")
        print(f"  the model-error term (--model-uncertainty 0.05: R_k = R_noise + Φ_k Σ_θ Φ_kᵀ per "
              f"sample) costs {e['ratio_csv_model_to_csv']:.2f}x the plain CSV -> CSV run (wall), "
              f"{e['ratio_parquet_model_to_parquet_cpu']:.2f}x the plain Parquet -> Parquet run (CPU); "
              f"CSV -> CSV with it / the pyarrow CSV reader alone = "
              f"{e['ratio_csv_model_to_pyarrow_anchor_cpu']:.2f}x CPU; load average {e['load_average_1min']:.1f} "
              f"(2 cores)")
        print(f"  anchors, the same CSV read alone: pandas.read_csv {e['anchor_pandas_read_csv_s']:.2f} s "
              f"(CPU {e['anchor_pandas_read_csv_cpu_s']:.2f} s), pyarrow.csv.read_csv "
              f"{e['anchor_pyarrow_read_csv_s']:.2f} s (CPU {e['anchor_pyarrow_read_csv_cpu_s']:.2f} s); "
              f"CSV -> CSV / pandas anchor = {e['ratio_csv_to_pandas_anchor']:.2f}x, / pyarrow anchor = "
              f"{e['ratio_csv_to_pyarrow_anchor']:.2f}x")
        for key, label in (("csv", "CSV -> CSV"), ("parquet", "Parquet -> Parquet")):
            print(f"  fresh process {label}: {e[key + '_subprocess_s']:.2f} s = "
                  f"{n / e[key + '_subprocess_s']:,.0f}/s wall, CPU {e[key + '_subprocess_cpu_s']:.2f} s = "
                  f"{n / e[key + '_subprocess_cpu_s']:,.0f}/CPU-s, peak RSS {e[key + '_peak_rss_MB']:.0f} MB")
        if "ten_million_s" in e:
            print(f"  10,000,000 samples CSV -> CSV: {e['ten_million_s']:.1f} s, CPU {e['ten_million_cpu_s']:.1f} s, "
                  f"peak RSS {e['ten_million_peak_rss_MB']:.0f} MB")
    if args.only == "end-to-end":
        return out
    off, st, pv = out["offline"], out["streaming"], out["dynamics_vs_pinocchio"]
    print(f"offline observer + dynamic localization, {off['samples']:,} samples (paper leg, moving, poked):")
    print(f"  observer {off['observer_s']:.3f} s, localize {off['localize_dynamic_s']:.3f} s, "
          f"whole estimate() {off['estimate_dynamic_s']:.3f} s -> {off['samples_per_s']:,.0f} samples/s wall, "
          f"{off['samples_per_cpu_s']:,.0f} per CPU-second "
          f"(observer+localize only: {off['observer_plus_localize_samples_per_s']:,.0f}/s; target >= 1,000,000/s)")
    print(f"  before (numpy forms, kernels off): {off['numpy_forms_samples_per_s']:,.0f} samples/s wall, "
          f"{off['numpy_forms_samples_per_cpu_s']:,.0f} per CPU-second -> compiled/numpy speed-up "
          f"{off['ratio_numpy_forms_over_compiled']:.2f}x (compiled kernels: {off['compiled_kernels']})")
    print(f"  with the model-error term (declared uncertainty, R_k per sample): "
          f"{off['ratio_model_over_plain']:.2f}x the plain estimate() in the same run, "
          f"+{off['model_term_us_per_sample']:.2f} us per sample wall, "
          f"+{off['model_term_cpu_us_per_sample']:.2f} us CPU")
    print(f"  detector alone (whitening + chi-square test) {off['detector_s']:.3f} s -> "
          f"{off['detector_samples_per_s']:,.0f} samples/s")
    print(f"  anchor: lfilter over 5 channels {off['anchor_lfilter_5ch_s']:.3f} s; estimate/anchor = "
          f"{off['ratio_estimate_to_lfilter_anchor']:.1f}x; max position error after 50 ms "
          f"{1e3 * off['position_error_max_m']:.3f} mm")
    print(f"streaming step(): median {st['median_us']:.1f} us, p99 {st['p99_us']:.1f} us "
          f"(target median <= 20 us); numpy 5x5 matvec anchor {st['anchor_numpy_matvec_median_us']:.2f} us "
          f"-> {st['ratio_step_to_matvec']:.1f}x")
    if "skipped" in pv:
        print(f"M, C, G vs pinocchio: {pv['skipped']}")
    else:
        print(f"M, C, G on {pv['states']:,} states: ours batched {pv['ours_batched_MCG_s']:.3f} s "
              f"(O(N) chain terms {pv['ours_chain_terms_s']:.3f} s), pinocchio looped "
              f"{pv['pinocchio_looped_s']:.3f} s -> pinocchio/ours = {pv['ratio_pinocchio_over_ours_MCG']:.1f}x "
              f"(matrices), {pv['ratio_pinocchio_over_ours_chain_terms']:.1f}x (chain terms)")
    return out


if __name__ == "__main__":
    main()
