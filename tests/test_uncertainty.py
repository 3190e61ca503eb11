"""Sensor uncertainty → localization error: two propagations checked against each other and
against the real observer + pipeline on noisy logs."""

import numpy as np
import pytest

from userio.errors import InputError
from estimator.log import SensorLog
from estimator.observer import residual_offline
from estimator.estimate import estimate
from estimator.robot import paper_leg
from estimator.sim.static import static_readings
from estimator.uncertainty import SensorNoise, first_order, monte_carlo

ROBOT = paper_leg()
F7 = 7.0 * np.array([np.cos(-np.pi / 3), np.sin(-np.pi / 3)])
POSTURES = np.array([[-0.4, -0.8], [0.9, -1.6], [0.5, -1.0], [-0.2, -1.4]])
NOISE = SensorNoise(torque_std_Nm=0.0133, wrench_std=[0.1, 0.1, 0.01], torque_gain_rel_std=0.0)


def _noisy_static_log(q_joint, link, alpha, force, noise, T, seed):
    """A fixed-base log holding one posture under one force, white noise on every reading."""
    rng = np.random.default_rng(seed)
    tau, W = static_readings(ROBOT, q_joint[None], link, alpha, force)
    q = np.concatenate([np.zeros(3), q_joint])
    sig_tau = np.broadcast_to(noise.torque_std_Nm, (ROBOT.n_links,))
    return SensorLog(t=np.arange(T) / noise.sample_rate_Hz, q=np.tile(q, (T, 1)),
                     dq=np.zeros((T, 5)), tau_Nm=tau + sig_tau * rng.standard_normal((T, 2)),
                     wrench=W + noise.wrench_std * rng.standard_normal((T, 3)), floating=False)


def test_filter_factor_matches_the_real_observer():
    """White noise σ through the exact observer leaves σ √((1 − a)/2), a = e^{−KΔt}."""
    log = _noisy_static_log(POSTURES[0], 2, 0.8, F7, NOISE, T=60000, seed=3)
    r = residual_offline(ROBOT.with_base(True), log.t, log.q, log.dq, log.tau_meas, 100.0)
    measured = r[1000:].std(axis=0)                      # settled (10/K)
    predicted = NOISE.filter_factor("dynamic") * NOISE.per_row(2)[0]
    np.testing.assert_allclose(measured, predicted, rtol=0.04)
    assert NOISE.filter_factor("paper") == 1.0


@pytest.mark.parametrize("method", ["dynamic", "paper"])
def test_first_order_agrees_with_monte_carlo(method):
    noise = SensorNoise(torque_std_Nm=0.0133, wrench_std=[0.1, 0.1, 0.01], torque_gain_rel_std=0.01)
    fo = first_order(ROBOT, POSTURES, 2, 0.6, F7, noise, method=method)
    mc = monte_carlo(ROBOT, POSTURES, 2, 0.6, F7, noise, draws=4000, rng=5, method=method)
    assert np.all(mc.flagged_fraction == 0)
    # 4000 draws: the sampled std has ≈ 1.1 % relative error; 5 % leaves room for non-linearity
    np.testing.assert_allclose(mc.alpha_std, fo.alpha_std, rtol=0.05)
    np.testing.assert_allclose(mc.position_rms_m, fo.position_rms_m, rtol=0.05)
    np.testing.assert_allclose(mc.force_rms_N, fo.force_rms_N, rtol=0.05)


def test_noise_free_sensors_give_exact_answers():
    quiet = SensorNoise(torque_std_Nm=0.0, wrench_std=[0, 0, 0], torque_gain_rel_std=0.0)
    mc = monte_carlo(ROBOT, POSTURES, 1, 0.5, np.array([5.0, 0.0]), quiet, draws=8)
    assert np.all(mc.position_rms_m < 1e-9) and np.all(mc.force_rms_N < 1e-9)


def test_monte_carlo_predicts_the_pipeline_on_a_noisy_log():
    """End to end: per-sample position error of `estimate` on a noisy hold ≈ the Monte Carlo figure."""
    q_joint, alpha = POSTURES[1], 0.8
    log = _noisy_static_log(q_joint, 2, alpha, F7, NOISE, T=30000, seed=11)
    est = estimate(ROBOT.with_base(False), log, method="dynamic", gain_per_s=100.0)
    settled = slice(1000, None)
    assert np.all(est.link[settled] == 2)
    tau, W = static_readings(ROBOT, q_joint[None], 2, alpha, F7)
    from estimator.dynamics import contact_point
    p_true = contact_point(ROBOT, np.r_[0, 0, 0, q_joint], 2, alpha)
    err = np.hypot(est.px[settled] - p_true[0], est.pz[settled] - p_true[1])
    predicted = monte_carlo(ROBOT, q_joint, 2, alpha, F7, NOISE, draws=4000, rng=2)
    rms = np.sqrt(np.mean(err ** 2))
    print(f"pipeline RMS position error {rms * 1e3:.3f} mm, predicted {predicted.position_rms_m[0] * 1e3:.3f} mm")
    np.testing.assert_allclose(rms, predicted.position_rms_m[0], rtol=0.10)


def test_force_along_the_link_is_flagged_not_guessed():
    """A force along link 2's axis passes through the knee: it is indistinguishable from a knee
    contact on link 1, and from any point of link 2. The answer must be refused, not a guess."""
    from estimator.dynamics import forward_kinematics
    q_joint = POSTURES[1]
    joints, _ = forward_kinematics(ROBOT, np.r_[0, 0, 0, q_joint])
    axis = (joints[2] - joints[1]) / np.linalg.norm(joints[2] - joints[1])
    mc = monte_carlo(ROBOT, q_joint, 2, 0.5, 5.0 * axis, NOISE, draws=200)
    assert mc.flagged_fraction[0] > 0.95


def test_bad_noise_and_contact_are_input_errors():
    with pytest.raises(InputError, match="wrench_std"):
        SensorNoise(torque_std_Nm=0.01, wrench_std=[0.1, 0.1], torque_gain_rel_std=0)
    with pytest.raises(InputError, match="torque_std_Nm"):
        SensorNoise(torque_std_Nm=-1, wrench_std=[0.1, 0.1, 0.01], torque_gain_rel_std=0)
    with pytest.raises(InputError, match="link"):
        monte_carlo(ROBOT, POSTURES, 3, 0.5, F7, NOISE, draws=10)


def test_propagate_cli_json(capsys):
    import json

    from torquebench.cli import main

    assert main(["propagate", "--grid", "3", "--draws", "50", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    dyn_, paper = out["methods"]["dynamic"], out["methods"]["paper"]
    assert out["postures"] == 9 and out["torque_noise_std_Nm"] > 0
    # filtering + all rows beat the raw quasi-static paper method on the median posture
    assert dyn_["position_rms_median_m"] < paper["position_rms_median_m"]


def test_propagate_cli_bad_input_exits_2(capsys):
    from torquebench.cli import main

    assert main(["propagate", "--force", "7"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--force" in err


def test_percentile_and_rms_standard_errors_match_the_spread_over_seeds():
    """The reported MC standard errors equal the scatter of the figure over 60 independent runs."""
    runs = [monte_carlo(ROBOT, POSTURES[:2], 2, 0.6, F7, NOISE, draws=400, rng=seed, method="paper")
            for seed in range(60)]
    p95 = np.array([r.position_p95_m for r in runs])
    rms = np.array([r.position_rms_m for r in runs])
    se95 = np.mean([r.position_p95_se_m for r in runs], axis=0)
    se_rms = np.mean([r.position_rms_se_m for r in runs], axis=0)
    # the std of 60 draws is itself known to ~±9 % (1σ); allow ±35 %
    np.testing.assert_allclose(se95, p95.std(axis=0, ddof=1), rtol=0.35)
    np.testing.assert_allclose(se_rms, rms.std(axis=0, ddof=1), rtol=0.35)


def test_propagate_json_carries_the_error_estimates(capsys):
    import json

    from torquebench.cli import main

    assert main(["propagate", "--grid", "2", "--draws", "200", "--json"]) == 0
    m = json.loads(capsys.readouterr().out)["methods"]["dynamic"]
    assert 0 < m["position_p95_max_m_error_estimate"] < m["position_p95_max_m"]
    assert "standard error" in m["position_p95_max_m_error_method"]
    assert 0 < m["position_rms_median_m_error_estimate"] < m["position_rms_median_m"]


def test_model_uncertainty_enters_the_settled_residual_exactly_and_both_propagations_agree():
    """The file's gravity minus the robot's at a posture is −Y_u(q, 0) (θ_file − θ) (linear in θ,
    estimator.model), which is what both propagations add; they agree where the localizer is
    smooth, and a declared uncertainty widens the predicted error."""
    from estimator import dynamics as dyn
    from estimator import inertial
    from estimator.model import ModelUncertainty

    decl = ModelUncertainty(0.05, 0.10, 0.003)
    true = inertial.perturbed(ROBOT, decl, 3).with_base(True)
    file = ROBOT.with_base(True)
    q = np.concatenate([np.zeros((len(POSTURES), 3)), POSTURES], axis=1)
    _, Yu = file.momentum_regressor(q, np.zeros_like(q))
    dG = dyn.gravity_vector(file, q) - dyn.gravity_vector(true, q)
    np.testing.assert_allclose(dG, -Yu @ (file.parameters() - true.parameters()), atol=1e-12)
    cov = ROBOT.parameter_covariance(decl)
    noise = SensorNoise(torque_std_Nm=0.005, wrench_std=[0.1, 0.1, 0.01], torque_gain_rel_std=0.0)
    F = np.array([3.5, -6.06])
    fo = first_order(ROBOT, POSTURES, 2, 0.6, F, noise, parameter_cov=cov)
    mc = monte_carlo(ROBOT, POSTURES, 2, 0.6, F, noise, draws=3000, rng=1, parameter_cov=cov)
    bare = first_order(ROBOT, POSTURES, 2, 0.6, F, noise)
    ok = mc.flagged_fraction < 0.01
    assert ok.sum() >= 2
    np.testing.assert_allclose(mc.position_rms_m[ok], fo.position_rms_m[ok], rtol=0.15)
    assert np.all(fo.position_rms_m > 2 * bare.position_rms_m)
