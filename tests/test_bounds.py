"""Cramér–Rao bounds (estimator.bounds): the Fisher information against finite differences, the
noise terms against a simulation of the residual's noise, the per-sample bound against a Monte
Carlo of the localizer, and the episode (long-run) information against the exact information
of the correlated Gaussian model."""

import numpy as np
import pytest

from estimator import bounds
from estimator import dynamics as D
from estimator.localization import localize_dynamic
from estimator.noise import NoiseModel, filter_terms, residual_covariance
from estimator.robot import paper_leg

ROBOT = paper_leg()
FULL = ROBOT.with_base(True)
NOISE = NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01])


def _posture(q1=0.4, q2=-1.1):
    return np.array([0.0, 0.0, 0.0, q1, q2])


def _mean(q, link, alpha, F):
    return D.point_jacobian(FULL, q[None], link, alpha)[0].T @ F


@pytest.mark.parametrize("link", [1, 2])
def test_design_matches_finite_differences(link):
    q = _posture()
    F = np.array([2.0, -3.0])
    H, length = bounds.design(ROBOT, q[None], link, 0.37, F)
    h = 1e-6
    dA = (_mean(q, link, 0.37 + h, F) - _mean(q, link, 0.37 - h, F)) / (2 * h)
    dFx = (_mean(q, link, 0.37, F + [h, 0]) - _mean(q, link, 0.37, F - [h, 0])) / (2 * h)
    dFz = (_mean(q, link, 0.37, F + [0, h]) - _mean(q, link, 0.37, F - [0, h])) / (2 * h)
    np.testing.assert_allclose(H[0], np.stack([dA, dFx, dFz], -1), atol=1e-8)
    assert length[0] == pytest.approx(ROBOT.lengths_m[link - 1])


def test_noise_terms_against_a_simulated_residual():
    """R, Γ₁ = Cov(r_{k+1}, r_k) and the long-run Ω (batch means of 200-sample blocks) of a long
    simulated no-contact residual (white sensor noise through the observer's exact filter)."""
    from scipy.signal import lfilter

    q = _posture()[None]
    dq = np.zeros_like(q)
    noise = NoiseModel(torque_sigma_Nm=[0.005, 0.008], ft_sigma=[0.1, 0.12, 0.01],
                       velocity_sigma_rad_per_s=0.002)        # q̇ noise: R and Ω differ in shape
    nt = bounds.noise_terms(ROBOT, q, dq, noise, 100.0, 1e-3)
    R, G1, Om = nt.R, nt.G1, nt.Omega
    np.testing.assert_allclose(R[0], residual_covariance(ROBOT, q, dq, noise, 100.0, 1e-3)[0], rtol=1e-12)
    a, b, B0, B1 = filter_terms(ROBOT, q, dq, noise, 100.0, 1e-3)
    rng = np.random.default_rng(3)
    T = 1_000_000
    e = rng.standard_normal((T + 1, B0.shape[2]))
    d = e[1:] @ B0[0].T + e[:-1] @ B1[0].T
    r = np.stack([lfilter([b[i]], [1, -a[i]], d[:, i]) for i in range(5)], -1)[1000:]
    sd = np.sqrt(np.diag(R[0]))
    emp_R = np.cov(r.T)
    emp_G1 = (r[1:] - r.mean(0)).T @ (r[:-1] - r.mean(0)) / (len(r) - 1)
    assert np.max(np.abs(emp_R - R[0]) / np.outer(sd, sd)) < 0.03
    assert np.max(np.abs(emp_G1 - G1[0]) / np.outer(sd, sd)) < 0.03
    m = 200
    blocks = r[: len(r) // m * m].reshape(-1, m, 5).mean(1)
    emp_Om = np.cov(blocks.T) * m
    so = np.sqrt(np.diag(Om[0]))
    assert np.max(np.abs(emp_Om - Om[0]) / np.outer(so, so)) < 0.1     # ~5000 blocks: 2 % SE
    # the q̇ noise enters each sample through M/Δt and cancels in the long run: per sample the
    # hip rows hold ≥ 3× the share white τ/FT noise alone would give them (R = Ω b/2)
    assert np.all(np.diag(R[0])[2:4] > 3 * (b[2:4] / 2) * np.diag(Om[0])[2:4])


def test_sample_terms_recover_the_model_from_a_quiet_stretch():
    from scipy.signal import lfilter

    q = _posture()[None]
    nt = bounds.noise_terms(ROBOT, q, np.zeros_like(q), NOISE, 100.0, 1e-3)
    a, b, B0, B1 = filter_terms(ROBOT, q, np.zeros_like(q), NOISE, 100.0, 1e-3)
    rng = np.random.default_rng(5)
    e = rng.standard_normal((200_001, B0.shape[2]))
    d = e[1:] @ B0[0].T + e[:-1] @ B1[0].T
    r = np.stack([lfilter([b[i]], [1, -a[i]], d[:, i]) for i in range(5)], -1)[500:]
    est = bounds.sample_terms(r, nt.R[0], a)
    so = np.sqrt(np.diag(nt.Omega[0]))
    assert np.max(np.abs(est.Omega[0] - nt.Omega[0]) / np.outer(so, so)) < 0.03
    for got, want in ((est.S0, nt.S0), (est.S1, nt.S1), (est.G1, nt.G1)):
        sd = np.sqrt(np.diag(want[0] if want is not nt.G1 else nt.R[0]))
        assert np.max(np.abs(got[0] - want[0]) / np.outer(sd, sd)) < 0.05


@pytest.mark.parametrize("link,alpha,angle", [(2, 0.6, -1.0), (1, 0.3, 2.2), (2, 0.15, 0.4)])
def test_per_sample_bound_is_reached_by_the_whitened_localizer(link, alpha, angle):
    """Monte Carlo of r = J(α)ᵀF + n, n ~ N(0, R): the R⁻¹-weighted fit's α spread equals the
    bound (efficient at this signal-to-noise ratio) and the force's too; the unweighted fit is
    worse (what the estimator did before)."""
    q = _posture()
    F = 4.0 * np.array([np.cos(angle), np.sin(angle)])
    R = residual_covariance(ROBOT, q[None], np.zeros((1, 5)), NOISE, 100.0, 1e-3)[0]
    bound = bounds.per_sample(ROBOT, q[None], link, alpha, F, R)
    draws = 4000
    rng = np.random.default_rng(11)
    r = _mean(q, link, alpha, F) + rng.multivariate_normal(np.zeros(5), R, draws)
    qs = np.repeat(q[None], draws, 0)
    fit = localize_dynamic(ROBOT, qs, r, weight=np.linalg.inv(R), ambiguity_tol=0.0)
    ok = fit.link == link
    assert ok.mean() > 0.99
    err = fit.alpha[ok] - alpha
    rms = np.sqrt(np.mean(err ** 2))
    se = rms / np.sqrt(2 * ok.sum())
    assert abs(rms / bound.alpha_std[0] - 1) < 4 * se / rms + 0.01
    f_rms = np.sqrt(np.mean((fit.force_N[ok] - F) ** 2, axis=0))
    np.testing.assert_allclose(f_rms, bound.force_std_N[0], rtol=0.08)
    plain = localize_dynamic(ROBOT, qs, r, ambiguity_tol=0.0)
    assert np.sqrt(np.nanmean((plain.alpha - alpha) ** 2)) > 1.05 * rms


def test_bound_diverges_as_the_force_turns_along_the_link():
    q = _posture()
    R = residual_covariance(ROBOT, q[None], np.zeros((1, 5)), NOISE, 100.0, 1e-3)[0]
    joints, _ = D.forward_kinematics(FULL, q[None])
    d = joints[0, 2] - joints[0, 1]
    phi = np.arctan2(d[1], d[0])
    offs = np.array([0.5, 0.1, 0.01, 0.001])
    s = [bounds.per_sample(ROBOT, q[None], 2, 0.5, 3 * np.array([np.cos(phi + o), np.sin(phi + o)]),
                           R).alpha_std[0] for o in offs]
    assert np.all(np.diff(s) > 0)
    np.testing.assert_allclose(np.array(s[1:]) * np.sin(offs[1:]), s[1] * np.sin(offs[1]), rtol=0.02)


def _exact_episode_information(H, J, R, G1, a):
    """The profiled information on α of L samples r_k = J_kᵀF_k + h_k δα + n_k, F_k free, n the
    stationary residual noise (Cov(n_k, n_l) = A^(k−l−1) Γ₁ for k > l, R at lag 0): dense."""
    L, n = H.shape
    Gam = np.zeros((L * n, L * n))
    P = [np.eye(n)]
    for j in range(1, L):
        P.append(np.diag(a ** (j - 1)) @ G1)
    for k in range(L):
        Gam[k * n:(k + 1) * n, k * n:(k + 1) * n] = R
        for l in range(k):
            Gam[k * n:(k + 1) * n, l * n:(l + 1) * n] = P[k - l]
            Gam[l * n:(l + 1) * n, k * n:(k + 1) * n] = P[k - l].T
    h = H.reshape(-1)
    G = np.zeros((L * n, 2 * L))
    for k in range(L):
        G[k * n:(k + 1) * n, 2 * k:2 * k + 2] = J[k]
    C = np.linalg.cholesky(Gam)
    hw = np.linalg.solve(C, h)
    Gw = np.linalg.solve(C, G)
    coef, *_ = np.linalg.lstsq(Gw, hw, rcond=None)
    res = hw - Gw @ coef
    return float(res @ res)


@pytest.mark.parametrize("velocity_sigma", [0.0, 0.003])
def test_episode_information_matches_the_exact_correlated_model(velocity_sigma):
    """Σ h Ω⊥ h (long-run) against the exact information of L = 300 correlated samples with a
    constant force: the exact one is (1 + (1 + a)/((1 − a) L)) times it (a stationary start's edge), to 1.5 %."""
    q = _posture()
    noise = NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01],
                       velocity_sigma_rad_per_s=velocity_sigma)
    nt = bounds.noise_terms(ROBOT, q[None], np.zeros((1, 5)), noise, 100.0, 1e-3)
    R, G1, Om = nt.R[0], nt.G1[0], nt.Omega[0]
    a, *_ = filter_terms(ROBOT, q[None], np.zeros((1, 5)), noise, 100.0, 1e-3)
    F = np.array([2.0, -3.0])
    L = 200
    H, _ = bounds.design(ROBOT, q[None], 2, 0.6, F)
    J = np.swapaxes(D.point_jacobian(FULL, q[None], 2, 0.6), 1, 2)[0]
    exact = _exact_episode_information(np.repeat(H[:, :, 0], L, 0), np.repeat(J[None], L, 0), R, G1, a)
    longrun = L * bounds.episode_information(ROBOT, q[None], 2, 0.6, F, Om)[0]
    a0 = a[0]
    assert exact / longrun == pytest.approx(1 + (1 + a0) / ((1 - a0) * L), rel=0.015)
    # and the episode carries L·KΔt/2 samples' worth of the per-sample information (white τ/FT)
    if velocity_sigma == 0:
        ps = bounds.profiled(bounds.fisher(H, R))[0]
        assert longrun / ps == pytest.approx(L * (1 - a[0]) / 2, rel=0.01)


@pytest.mark.parametrize("velocity_sigma", [0.0, 0.003])
def test_restarted_episode_carries_the_long_run_information_of_its_steps(velocity_sigma):
    """The episode estimator's data: the observer restarted at the onset (estimator.onset), L
    samples = L drive steps with the force free per sample. Its exact information (dense, built
    from the sensor noise through the filter) is (L + 1) times the long-run share of a step (the
    episode bound of estimator.episode) to 0.2 % for every L; with a joint-rate noise a little less
    (its per-step share averages out over the first steps: 12 % at L = 15, 2.4 % at L = 80)."""
    q = _posture()
    noise = NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01],
                       velocity_sigma_rad_per_s=velocity_sigma)
    a, b, B0, B1 = (x[0] if np.ndim(x) == 3 else x for x in
                    filter_terms(ROBOT, q[None], np.zeros((1, 5)), noise, 100.0, 1e-3))
    Om = bounds.noise_terms(ROBOT, q[None], np.zeros((1, 5)), noise, 100.0, 1e-3).Omega
    F = np.array([2.0, -3.0])
    H, _ = bounds.design(ROBOT, q[None], 2, 0.6, F)
    h = H[0, :, 0]
    J = np.swapaxes(D.point_jacobian(FULL, q[None], 2, 0.6), 1, 2)[0]
    per = bounds.episode_information(ROBOT, q[None], 2, 0.6, F, Om)[0]
    n, m = B0.shape
    for L in (15, 40, 80):
        M = np.zeros((L * n, (L + 1) * m))         # r̃_k = Σ_{i<k} A^(k−1−i) b (B0 e_{i+1} + B1 e_i)
        for k in range(1, L + 1):
            for i in range(k):
                c = (a ** (k - 1 - i) * b)[:, None]
                M[(k - 1) * n:k * n, (i + 1) * m:(i + 2) * m] += c * B0
                M[(k - 1) * n:k * n, i * m:(i + 1) * m] += c * B1
        Gam = M @ M.T
        ht = np.concatenate([(1 - a[0] ** k) * h for k in range(1, L + 1)])   # the filtered force
        G = np.zeros((L * n, 2 * L))
        for k in range(L):
            G[k * n:(k + 1) * n, 2 * k:2 * k + 2] = J
        C = np.linalg.cholesky(Gam)
        hw, Gw = np.linalg.solve(C, ht), np.linalg.solve(C, G)
        coef, *_ = np.linalg.lstsq(Gw, hw, rcond=None)
        exact = float((hw - Gw @ coef) @ (hw - Gw @ coef))
        if velocity_sigma == 0:
            assert exact / ((L + 1) * per) == pytest.approx(1.0, abs=0.002)
        else:       # the q̇ noise's per-step share averages out over the first steps
            assert 1 - 2.5 / L < exact / ((L + 1) * per) < 1.0


def test_bound_maps_estimator_reaches_the_bound_and_refuses_along_the_link():
    """estimator.bound_maps: where the force is well off the link our estimator's RMS equals the
    bound (Monte Carlo, 400 draws: ±4 %); within 1° of the link the bound has grown ≥ 50× and the
    estimator refuses (parallel_to_link) rather than answer."""
    from estimator.bound_maps import localization_maps

    postures = np.array([[0.4, -1.1], [1.2, 0.6], [-0.7, 1.9]])
    joints, _ = D.forward_kinematics(FULL, np.c_[np.zeros((3, 3)), postures])
    phi = np.arctan2(*(joints[0, 2] - joints[0, 1])[::-1])            # link 2 at the first posture
    dirs = phi + np.array([np.pi / 2, 1.0, 0.5, np.radians(0.5), -np.radians(0.8)])
    m = localization_maps(ROBOT, postures, 2, 0.6, 4.0, dirs, NOISE, draws=400, seed=2)
    good = m["sin_angle"] > 0.3
    ratio = m["estimator_rms_m"][good] / m["bound_per_sample_m"][good]
    assert np.all((ratio > 0.88) & (ratio < 1.15)), ratio
    assert np.all(m["bound_episode_m"] < m["bound_per_sample_m"])
    near = m["sin_angle"][0] < np.sin(np.radians(1.0))
    assert near.sum() == 2
    assert np.all(m["refused_fraction"][0, near] > 0.5) and np.all(np.isnan(m["estimator_rms_m"][0, near]))
    assert np.all(m["bound_per_sample_m"][0, near] > 50 * m["bound_per_sample_m"][0, 0])


def test_propagate_json_carries_the_bound_maps(capsys):
    import json

    from torquebench.cli import main

    assert main(["propagate", "--grid", "2", "--draws", "50", "--directions", "8", "--json"]) == 0
    b = json.loads(capsys.readouterr().out)["bounds"]
    assert len(b["per_sample_bound_m"]) == 4 and len(b["per_sample_bound_m"][0]) == 8
    assert len(b["directions_rad"]) == 8 and b["directions_rad"][0] == pytest.approx(-np.pi / 3)
    assert 0 < b["episode_bound_median_m"] < b["per_sample_bound_median_m"]
    assert 0.8 < b["estimator_over_bound_median"] < 1.25
    assert "Cramér–Rao" in b["method"]


def test_per_sample_alpha_variance_loop_matches_the_numpy_form(monkeypatch):
    from estimator import compiled

    rng = np.random.default_rng(8)
    T = 40
    q = np.c_[rng.normal(0, 0.02, (T, 3)), rng.uniform(-2, 2, (T, 2))]
    link = rng.integers(1, 3, T)
    alpha = rng.uniform(0, 1, T)
    F = rng.normal(0, 3, (T, 2))
    M = rng.normal(size=(3, 5, 5))
    Rinv = M @ np.swapaxes(M, 1, 2) + np.eye(5)
    ui = rng.integers(0, 3, T)
    fast = bounds.per_sample_alpha_var(ROBOT, q, link, alpha, F, Rinv, ui)
    monkeypatch.setattr(compiled, "ENABLED", False)
    ref = bounds.per_sample_alpha_var(ROBOT, q, link, alpha, F, Rinv, ui)
    np.testing.assert_allclose(fast, ref, rtol=1e-9)
    one = bounds.per_sample(ROBOT, q[:1], int(link[0]), alpha[0], F[0], np.linalg.inv(Rinv[ui[0]]))
    assert np.sqrt(ref[0]) == pytest.approx(one.alpha_std[0], rel=1e-9)
