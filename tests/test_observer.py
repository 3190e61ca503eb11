"""Momentum observer: streaming = offline, convergence to τ_ext = Jᵀ F, discretizations, gaps."""

import numpy as np
import pytest

from estimator import dynamics as D
from estimator import observer as O
from estimator.detection import detect, isolate
from userio.errors import InputError
from estimator.robot import paper_leg
from estimator.synthetic import moving_leg_poke

ROBOT = paper_leg()


@pytest.fixture(scope="module")
def moving():
    return moving_leg_poke(ROBOT, duration_s=1.0, frequency_Hz=1.0, t_on_s=0.3,
                           base_amplitude=(0.01, 0.01, 0.05))


def _tau_ext(log, truth):
    J = D.point_jacobian(ROBOT, log.q, 2, 0.5)
    return np.einsum("tak,ta->tk", J, np.nan_to_num(truth.force_N))


@pytest.mark.parametrize("method,gain", [("exact", 100.0), ("explicit", 100.0), ("exact", 1e4)])
def test_streaming_equals_offline(moving, method, gain):
    log, _ = moving
    dt = O.regular_period(log.t)
    r_off = O.residual_offline(ROBOT, log.t, log.q, log.dq, log.tau_meas, gain, method=method)
    obs = O.MomentumObserver(ROBOT, dt, gain, method=method)
    r_str = np.array([obs.step(log.q[k], log.dq[k], log.tau_meas[k]) for k in range(len(log.t))])
    err = np.abs(r_off - r_str).max()
    print(f"{method} K={gain}: max |offline − streaming| = {err:.1e}")
    assert err < 1e-12
    assert np.abs(r_off).max() > 1.0              # a real signal was compared


def test_residual_converges_to_external_force(moving):
    """r → Jᵀ F (forces ON the robot) with the first-order lag 1/K while the leg moves."""
    log, truth = moving
    K = 100.0
    r = O.residual_offline(ROBOT, log.t, log.q, log.dq, log.tau_meas, K)
    tau_ext = _tau_ext(log, truth)
    quiet = log.t < 0.3
    # no contact, moving leg: r stays at the trapezoid-rule truncation error Δt²/12 · |d³P/dt³|
    P, _ = O.momentum_terms(ROBOT, log.q, log.dq, log.tau_meas)
    P3 = np.abs(np.diff(P, 3, axis=0)).max() / 1e-3 ** 3
    bound = 1e-3 ** 2 / 12 * P3
    print(f"quiet |r| max {np.abs(r[quiet]).max():.2e}, truncation bound {bound:.2e}")
    assert np.abs(r[quiet]).max() < 2 * bound
    lag = O.lag_s(np.full(5, K), 1e-3)[0]
    assert abs(lag - 1 / K) < 1e-5
    shifted = np.stack([np.interp(log.t - lag, log.t, tau_ext[:, k]) for k in range(5)], -1)
    settled = log.t > 0.3 + 20 / K               # the step-on transient is 5 N · e^-20 ≈ 1e-8 N
    err = np.abs(r[settled] - shifted[settled]).max()
    print(f"moving leg: |r − τ_ext(t − lag)| max {err:.2e} (|τ_ext| up to {np.abs(tau_ext).max():.2f})")
    assert err < 2e-3
    # the force rows are the constant world force exactly once settled
    np.testing.assert_allclose(r[settled, :2], tau_ext[settled, :2], atol=2 * bound + 1e-8)


def test_exact_discretization_stable_at_K_dt_10_and_explicit_refused(moving):
    log, truth = moving
    dt = O.regular_period(log.t)
    K = 10.0 / dt
    r = O.residual_offline(ROBOT, log.t, log.q, log.dq, log.tau_meas, K)
    tau_ext = _tau_ext(log, truth)
    assert np.all(np.isfinite(r))
    # with K Δt = 10 the residual is the step-mean of τ_ext delayed by ~ half a step
    mid = 0.5 * (tau_ext[1:] + tau_ext[:-1])
    settled = log.t[1:] > 0.31
    assert np.abs(r[1:][settled] - mid[settled]).max() < 2e-3
    with pytest.raises(InputError, match="K·Δt"):
        O.residual_offline(ROBOT, log.t, log.q, log.dq, log.tau_meas, 2.0 / dt, method="explicit")
    with pytest.raises(InputError, match="unstable"):
        O.MomentumObserver(ROBOT, dt, 3.0 / dt, method="explicit")
    # just below the limit the explicit form still runs (and oscillates, as the paper's would)
    r_exp = O.residual_offline(ROBOT, log.t, log.q, log.dq, log.tau_meas, 1.9 / dt, method="explicit")
    assert np.all(np.isfinite(r_exp))


def test_explicit_matches_paper_equations(moving):
    """Eqs. 3–4 literally: p_int ← p_int + (u + r) Δt, r = K (P − p_int − P0)."""
    log, _ = moving
    K, dt = 50.0, 1e-3
    P, u = O.momentum_terms(ROBOT, log.q, log.dq, log.tau_meas)
    p_int = np.zeros(5)
    r = np.zeros(5)
    out = []
    for k in range(len(log.t)):
        r = K * (P[k] - p_int - P[0])
        out.append(r)
        p_int = p_int + (u[k] + r) * dt
    ours = O.residual_offline(ROBOT, log.t, log.q, log.dq, log.tau_meas, K, method="explicit")
    np.testing.assert_allclose(ours, np.array(out), atol=1e-10)


def test_gap_from_skipped_rows_is_taken_exactly(moving):
    log, _ = moving
    keep = np.ones(len(log.t), bool)
    keep[[100, 101, 450]] = False
    t, q, dq, tau = log.t[keep], log.q[keep], log.dq[keep], log.tau_meas[keep]
    r_off = O.residual_offline(ROBOT, t, q, dq, tau, 100.0)
    obs = O.MomentumObserver(ROBOT, 1e-3, 100.0)
    r_str = [obs.step(q[0], dq[0], tau[0])]
    r_str += [obs.step(q[k], dq[k], tau[k], dt_s=t[k] - t[k - 1]) for k in range(1, len(t))]
    assert np.abs(r_off - np.array(r_str)).max() < 1e-12


@pytest.mark.parametrize("method", ["exact", "explicit"])
def test_compiled_recursion_equals_lfilter_bit_for_bit(moving, monkeypatch, method):
    """The compiled observer recursion and scipy's lfilter (used without numba) evaluate
    y_k = b x_k + a y_{k−1} in the same order: the same bits, with a gap in the log too."""
    from estimator import compiled

    assert compiled.available()
    log, _ = moving
    keep = np.ones(len(log.t), bool)
    keep[[100, 101, 450]] = False
    args = (ROBOT, log.t[keep], log.q[keep], log.dq[keep], log.tau_meas[keep], 100.0)
    fast = O.residual_offline(*args, method=method)
    monkeypatch.setattr(O, "first_order", lambda *a: False)      # the lfilter path only
    ref = O.residual_offline(*args, method=method)
    assert np.abs(ref).max() > 1.0
    assert np.array_equal(fast, ref)


def test_long_log_is_numerically_sound():
    """1e5 samples of a constant τ_ext: no drift or overflow of the recurrence."""
    T = 100_000
    t = np.arange(T) * 1e-3
    q = np.tile([0, 0, 0, 0.9, -1.6], (T, 1))
    dq = np.zeros((T, 5))
    F = np.array([1.0, -2.0])
    J = D.point_jacobian(ROBOT, q[0], 1, 0.3)
    tau = D.gravity_vector(ROBOT, q) - J.T @ F
    r = O.residual_offline(ROBOT, t, q, dq, tau, 100.0)
    np.testing.assert_allclose(r[-1], J.T @ F, atol=1e-12)
    assert np.abs(r[1000:] - J.T @ F).max() < 1e-12


def test_gain_validation():
    with pytest.raises(InputError, match="gain"):
        O.gains(ROBOT, -1.0)
    with pytest.raises(InputError, match="5 values"):
        O.gains(ROBOT, [1.0, 2.0])
    assert O.gains(ROBOT, [1, 2, 3, 4, 5]).tolist() == [1, 2, 3, 4, 5]


def test_detection_debounce_and_isolation():
    rnorm = np.array([0, 1, 0, 1, 1, 1, 0, 1, 1], float)
    assert detect(rnorm, 0.5).tolist() == (rnorm > 0.5).tolist()
    assert detect(rnorm, 0.5, debounce=2).tolist() == [0, 0, 0, 0, 0, 1, 0, 0, 0]
    with pytest.raises(InputError):
        detect(rnorm, -1.0)
    r = np.array([[0.5, 0.0, 0.0], [0.5, 0.3, 0.0], [0.5, 0.3, 0.2], [0.0, 0.0, 0.0]])
    assert isolate(r, [0.1, 0.1, 0.1]).tolist() == [1, 2, 3, 0]
    assert isolate(r, [0.1, 0.1, 0.25]).tolist() == [1, 2, 2, 0]


def test_noise_thresholds_use_only_contact_free_samples():
    from estimator.detection import noise_thresholds

    rng = np.random.default_rng(0)
    r = rng.normal(0, 0.01, (1000, 2))
    r[200:] += 5.0                                  # a contact on most samples
    quiet = np.zeros(1000, bool)
    quiet[:200] = True
    thr = noise_thresholds(r, quiet, floor=0.001, n_sigma=5)
    assert np.all(np.abs(thr - 0.05) < 0.01)        # 5 σ of the quiet part, not of the contact
    assert noise_thresholds(r, np.zeros(1000, bool), floor=0.02).tolist() == [0.02, 0.02]
