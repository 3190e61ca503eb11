"""Extreme cases of the stability table: near-incompressible material (P1 locks, P2 holds),
tiny and huge sensors (1e-3 and 1e4 N·m full scale), float32 input (log and calibration)."""

import json

import numpy as np
import pytest

from calibration.fit import fit_session
from calibration.session import read_session
from calibration.simulate import PAPER_MASSES_G, SessionSpec, simulate_session
from flexure.convergence import richardson
from flexure.material import Material
from torquebench.cli import main
from torquebench.io import REPO_ROOT

# ------------------------------------------------------------------ ν → 0.5
from test_fem_validation import A_IN, lame      # the Lamé thick cylinder of the FEM validation


def lame_bore_hoop_strain(order: int, k: int, nu: float):
    """Quarter thick cylinder in plane strain (u_z = 0 on both faces), internal pressure: the hoop
    strain u_r/r at the bore, FEM and exact (Lamé: u_r = (1+ν)/E a²p/(b²−a²) ((1−2ν) r + b²/r)),
    and the solver's warnings. Plane strain makes ν → 0.5 incompressible: the locking test."""
    m, s, ur, ur_exact, _ = lame(order, k, Material(70e9, nu, 250e6, "near-incompressible"))
    bore = np.hypot(m.points[:, 0], m.points[:, 1]) < A_IN * (1 + 1e-9)
    return (float(np.mean(ur[bore] / A_IN)), float(np.mean(ur_exact[bore]) / A_IN), m.n_dofs,
            s.info["warnings"])


def test_near_incompressible_p2_stays_within_its_error_estimate_while_p1_locks():
    """ν = 0.45, 0.49, 0.499 against Lamé. P2 (two levels, Richardson/GCI estimate) is within its
    own error estimate and within 0.05 %; P1 on the same meshes is off by 2.3 %, 7 %, 20 % and its
    convergence stalls as ν → 0.5 (locking). P1 is flagged `near_incompressible` from ν = 0.49,
    P2 not (from 0.49999: tests/test_fem_incompressible.py)."""
    p1_err, p1_rate = {}, {}
    for nu in (0.45, 0.49, 0.499):
        p2 = [lame_bore_hoop_strain(2, k, nu) for k in (2, 4)]
        exact = p2[0][1]
        h = [1.0, 0.5]
        est, _, method = richardson(h, [p2[0][2], p2[1][2]], [p2[0][0], p2[1][0]], nominal_order=2)
        err2 = abs(p2[1][0] - exact)
        assert err2 <= est and err2 / exact < 5e-4, (nu, err2 / exact, est / exact)
        p1 = [lame_bore_hoop_strain(1, k, nu) for k in (2, 4)]
        e1 = [abs(v[0] / exact - 1) for v in p1]
        p1_err[nu], p1_rate[nu] = e1[1], np.log2(e1[0] / e1[1])
        assert e1[1] > 20 * err2 / exact                      # P1 far worse than P2 on the same mesh
        assert "near_incompressible" not in p2[1][3]         # P2 is flagged only from ν = 0.49999
        assert ("near_incompressible" in p1[1][3]) == (nu >= 0.49)
    assert p1_err[0.45] > 0.02 and p1_err[0.49] > 0.06 and p1_err[0.499] > 0.18
    assert p1_rate[0.45] > 1.5 and p1_rate[0.499] < 0.5      # P1 converges at ~h², then stalls


# ------------------------------------------------------------------ tiny and huge sensors
RATED_STRAIN = 1e-3          # strain at full scale, whatever the full-scale torque


@pytest.mark.parametrize("full_scale_Nm", [1e-3, 1e4])
def test_tiny_and_huge_sensor_chain_is_exact_relative_to_its_scale(full_scale_Nm):
    """The chain sees only strain: a 1e-3 or 1e4 N·m sensor gives the 2 N·m sensor's ADC codes at
    the same fraction of full scale, the same relative noise and the same relative read-back."""
    from bridge.chain import paper_chain

    ref = paper_chain(strain_per_Nm=RATED_STRAIN / 2.0)
    ch = paper_chain(strain_per_Nm=RATED_STRAIN / full_scale_Nm)
    x = np.linspace(-1.0, 1.0, 2001)
    c_ref, c = ref.counts(2.0 * x, rng=5), ch.counts(full_scale_Nm * x, rng=5)
    assert np.max(np.abs(c - c_ref)) <= 1 and np.mean(c != c_ref) < 1e-3
    back = ch.torque_from_counts(c) / full_scale_Nm
    back_ref = ref.torque_from_counts(c_ref) / 2.0
    same = c == c_ref
    np.testing.assert_allclose(back[same], back_ref[same], rtol=1e-12, atol=1e-15)
    assert np.all(np.isfinite(back)) and np.max(np.abs(back - x)) < 20 * ch.noise_std_Nm / full_scale_Nm
    assert ch.noise_std_Nm / full_scale_Nm == pytest.approx(ref.noise_std_Nm / 2.0, rel=1e-12)
    assert ch.counts_per_Nm * full_scale_Nm == pytest.approx(ref.counts_per_Nm * 2.0, rel=1e-12)


@pytest.mark.parametrize("full_scale_Nm", [1e-3, 1e4])
def test_tiny_and_huge_sensor_calibration_fit_is_correct_relative_to_its_scale(full_scale_Nm):
    """Masses scaled so the heaviest gives full scale (1e-3 N·m: 0.5 g; 1e4 N·m: 5 t at 0.205 m):
    the emcee fit recovers the slope within its error estimate, and that estimate relative to the
    slope is the 2 N·m sensor's (the fit has no absolute epsilon)."""
    def fit_at(fs):
        scale = fs / 2.0                                    # the paper's 1000 g is 2.0 N·m
        spec = SessionSpec(slope_mV_per_g=0.0115 / scale, offset_mV=5.0069,
                           masses_g=tuple(m * scale for m in PAPER_MASSES_G), repeats=3,
                           repeat_noise_mV=0.02)
        s = simulate_session(spec, np.random.default_rng(7))
        f = fit_session(s, "linear", seed=1)
        return spec, f

    spec_ref, ref = fit_at(2.0)
    spec, fit = fit_at(full_scale_Nm)
    assert fit.converged and np.all(np.isfinite(fit.mean))
    slope, slope_sd = fit.mean[0], fit.std[0]
    assert abs(slope - spec.slope_mV_per_g) < 4 * slope_sd
    assert slope_sd / slope == pytest.approx(ref.std[0] / ref.mean[0], rel=0.05)
    assert fit.mean[1] == pytest.approx(ref.mean[1], abs=4 * ref.std[1])      # offset (mV): same scale


# ------------------------------------------------------------------ float32 input
def _intervals(capsys, path):
    assert main(["estimate", str(path), "--json"]) == 0
    return json.loads(capsys.readouterr().out)["intervals"]


def test_float32_sensor_log_changes_the_estimate_by_far_less_than_its_error_estimate(tmp_path, capsys):
    """examples/leg_poke stored as Parquet float32 columns and as CSV with 7 significant digits:
    every episode figure moves by < 1 % of its own 1σ error estimate (measured: ≤ 3e-5 of it)."""
    import pandas as pd

    src = REPO_ROOT / "examples" / "leg_poke" / "leg_poke.csv"
    df = pd.read_csv(src)
    df.astype("float32").to_parquet(tmp_path / "f32.parquet", index=False)
    assert set(pd.read_parquet(tmp_path / "f32.parquet").dtypes) == {np.dtype("float32")}
    df.to_csv(tmp_path / "d7.csv", index=False, float_format="%.7g")
    base = _intervals(capsys, src)
    assert len(base) == 1
    for path in (tmp_path / "f32.parquet", tmp_path / "d7.csv"):
        got = _intervals(capsys, path)
        assert len(got) == len(base)
        for a, b in zip(base, got):
            assert a["link"] == b["link"]
            for k in ("alpha", "Fx_N", "Fz_N", "px_m", "pz_m"):
                assert abs(a[k] - b[k]) < 0.01 * a[f"{k}_error_estimate"], (path.name, k)


def test_float32_calibration_csv_changes_the_fit_by_far_less_than_its_error_estimate(tmp_path):
    """The shipped session with readings rounded to float32 and written with 7 significant digits:
    the exact posterior moves by < 1 % of the coefficients' σ, and the emcee means (same seed) by
    less than their Monte Carlo error (3 × the standard error of the difference): once one
    accept/reject decision flips, the two chains are independent draws (1.4 % of σ on the slope
    on one machine, 0 on another, where no decision flipped)."""
    src = REPO_ROOT / "calibration" / "data" / "paper_link1_session.csv"
    lines = src.read_text().splitlines()
    header = lines[1].split(",")
    i = header.index("reading")
    out = lines[:2]
    for ln in lines[2:]:
        f = ln.split(",")
        f[i] = f"{np.float32(float(f[i])):.7g}"
        out.append(",".join(f))
    (tmp_path / "f32.csv").write_text("\n".join(out) + "\n")
    a, b = read_session(src), read_session(tmp_path / "f32.csv")
    assert not np.array_equal(a.reading, b.reading)
    fa, fb = fit_session(a, "linear", seed=3), fit_session(b, "linear", seed=3)
    assert np.all(np.abs(fa.exact.beta - fb.exact.beta) < 0.01 * fa.exact.std)
    mcse = np.hypot(fa.mc_standard_error[:2], fb.mc_standard_error[:2])
    assert np.all(np.abs(fa.mean[:2] - fb.mean[:2]) < 3.0 * mcse)
    assert np.all(mcse < 0.1 * fa.std[:2])                  # and that error is small
