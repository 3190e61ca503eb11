"""Simulator physics: energy balance, static equilibrium, mount/constraint wrench, stability."""

from dataclasses import replace

import numpy as np
import pytest

from estimator import dynamics as dyn
from userio.errors import InputError
from estimator.robot import paper_leg
from estimator.sim import (Controller, Ground, Poke, Sensors, SimConfig, check_stability, simulate,
                           static_readings)

QUIET = Sensors(torque_noise_Nm=0.0, ft_noise=np.zeros(3))


def cfg(**kw):
    base = dict(robot=paper_leg(), controller=Controller(q0_rad=np.array([-0.4, -0.8])),
                duration_s=0.3, sensors=QUIET)
    base.update(kw)
    return SimConfig(**base)


def test_energy_conserved_without_damping_or_control():
    """K_P = K_D = 0, D_b = 0: T + V_gravity + ½ Σ K_b x_b² is constant (independent of M's form)."""
    c = cfg(controller=Controller(q0_rad=np.array([0.5, -0.3]), kp=0.0, kd=0.0),
            mount_stiffness=np.array([5000.0, 5000.0, 500.0]), mount_damping=np.zeros(3),
            integrator="DOP853", rtol=1e-10, atol=1e-12, duration_s=0.5)
    res = simulate(c)
    T, V = dyn.energy(paper_leg(), res.q, res.dq)
    E = T + V + 0.5 * np.sum(np.array([5000.0, 5000.0, 500.0]) * res.q[:, :3] ** 2, axis=1)
    assert np.ptp(T) > 0.05                    # a real swing
    assert np.ptp(E) < 1e-6 * np.ptp(T)


def test_static_readings_balance_forces_and_moments():
    """Whole-body balance: W + F + Σ m g = 0 and moments about the hip (independent of J, G)."""
    rng = np.random.default_rng(0)
    robot = paper_leg()
    B = 50
    q = rng.uniform(-np.pi, np.pi, (B, 2))
    link = rng.integers(1, 3, B)
    alpha = rng.uniform(0, 1, B)
    F = rng.normal(0, 5, (B, 2))
    tau, W = static_readings(robot, q, link, alpha, F)
    full = robot.with_base(True)
    qf = np.concatenate([np.zeros((B, 3)), q], 1)
    _, coms = dyn.forward_kinematics(full, qf)
    m_tot = robot.base_mass_kg + robot.masses_kg.sum()
    g = robot.gravity_m_per_s2
    assert np.allclose(W[:, 0], -F[:, 0], atol=1e-12)
    assert np.allclose(W[:, 1], m_tot * g - F[:, 1], atol=1e-12)
    p = np.array([dyn.contact_point(full, qf[i], link[i], alpha[i]) for i in range(B)])
    p_cross_F = p[:, 0] * F[:, 1] - p[:, 1] * F[:, 0]
    My = -p_cross_F + g * np.einsum("i,bi->b", robot.masses_kg, coms[..., 0])
    assert np.allclose(W[:, 2], My, atol=1e-12)
    # knee torque: moment about the knee of everything beyond it
    knee = dyn.forward_kinematics(full, qf)[0][:, 1]
    on2 = link == 2
    r = p - knee
    t2 = g * robot.masses_kg[1] * (coms[:, 1, 0] - knee[:, 0]) - np.where(on2, r[:, 0] * F[:, 1] - r[:, 1] * F[:, 0], 0)
    assert np.allclose(tau[:, 1], t2, atol=1e-12)


def test_settled_rigid_and_stiff_mounts_read_the_static_wrench():
    """A held poke, after settling: rigid weld and stiff-spring mount both read static_readings."""
    poke = (Poke(1, 0.5, 5.0, -np.pi / 3, 0.0, 10.0),)
    ctrl = Controller(q0_rad=np.array([-0.4, -0.8]), kp=500.0, kd=10.0)
    for base in ("rigid", "fixed"):
        res = simulate(cfg(base=base, pokes=poke, controller=ctrl, duration_s=0.6))
        qj = res.q[-1, 3:]
        tau, W = static_readings(paper_leg(), qj, 1, 0.5, poke[0].force_N)
        assert np.abs(res.dq[-1]).max() < 1e-4
        assert np.allclose(res.wrench[-1], W[0], atol=2e-3), base
        assert np.allclose(res.tau_Nm[-1], tau[0], atol=1e-3), base


def test_zoh_at_1kHz_is_refused_with_a_clear_message():
    c = cfg(controller=Controller(q0_rad=np.array([-0.4, -0.8]), mode="zoh", rate_Hz=1000.0))
    with pytest.raises(InputError, match=r"zero-order-hold PD at 1000 Hz.*spectral radius.*≥ 1"):
        simulate(c)
    rep = check_stability(c)
    assert not rep.stable and rep.zoh_spectral_radius > 10 and 1e4 < rep.min_stable_zoh_rate_Hz < 2e4
    assert rep.fastest_pole_per_s == pytest.approx(2.96e4, rel=0.05)


def test_zoh_stability_threshold_matches_the_nonlinear_simulation():
    """Below the predicted minimum ZOH rate the nonlinear sim diverges; above it, it holds."""
    c = cfg(controller=Controller(q0_rad=np.array([-0.4, -0.8]), mode="zoh", rate_Hz=1000.0))
    f_min = check_stability(c).min_stable_zoh_rate_Hz
    assert 12000 < f_min < 20000
    poke = (Poke(2, 0.5, 1.0, 0.0, 0.0, 1.0),)
    runs = {}
    for rate in (12000.0, 20000.0):
        zc = replace(c, controller=replace(c.controller, rate_Hz=rate), duration_s=0.03,
                     pokes=poke, integrator="RK4", fixed_step_s=1.0 / rate)
        assert check_stability(zc).stable == (rate > f_min)
        try:
            runs[rate] = np.abs(simulate(zc, check=False).dq[-1, 3:]).max()
        except InputError:          # diverged to non-finite values
            runs[rate] = np.inf
    assert runs[20000.0] < 1.0 and runs[12000.0] > 1e3


def test_zoh_fast_enough_agrees_with_continuous_control():
    poke = (Poke(2, 0.8, 7.0, -np.pi / 3, 0.02, 0.08),)
    cont = simulate(cfg(pokes=poke, duration_s=0.1))
    zoh = simulate(cfg(pokes=poke, duration_s=0.1, integrator="RK4", fixed_step_s=2.5e-5,
                       controller=Controller(q0_rad=np.array([-0.4, -0.8]), mode="zoh", rate_Hz=40000.0)))
    assert np.abs(cont.q - zoh.q).max() < 2e-4
    assert np.abs(cont.wrench - zoh.wrench).max() < 0.05


def test_rk4_refused_when_step_too_large_and_converges_when_small():
    big = cfg(integrator="RK4", fixed_step_s=1e-3)
    with pytest.raises(InputError, match="RK4 with h = 0.001 s is unstable"):
        simulate(big)
    poke = (Poke(2, 0.8, 7.0, -np.pi / 3, 0.01, 0.04),)
    ref = simulate(cfg(integrator="Radau", rtol=1e-10, atol=1e-12, duration_s=0.05, pokes=poke))
    err = {}
    for h in (5e-5, 2.5e-5):
        rk4 = simulate(cfg(integrator="RK4", fixed_step_s=h, duration_s=0.05, pokes=poke))
        err[h] = np.abs(rk4.tau_Nm - ref.tau_Nm).max()
    assert err[5e-5] < 1e-6 and err[2.5e-5] < err[5e-5] / 4   # ≥ 2nd order seen (4th nominal)


def test_rk45_and_bdf_agree():
    poke = (Poke(1, 0.5, 5.0, -np.pi / 3, 0.05, 0.15),)
    a = simulate(cfg(integrator="RK45", duration_s=0.2, pokes=poke, rtol=1e-7, atol=1e-9))
    b = simulate(cfg(integrator="BDF", duration_s=0.2, pokes=poke, rtol=1e-7, atol=1e-9))
    assert np.abs(a.wrench - b.wrench).max() < 5e-3
    assert b.stats["rhs_evaluations"] < a.stats["rhs_evaluations"]   # stiff: implicit is cheaper


def test_poke_profiles_ramps_and_zero_window():
    p = Poke(1, 0.5, 2.0, 0.0, 0.1, 0.3, ramp_s=0.1)
    t = np.array([0.0, 0.1, 0.15, 0.2, 0.3, 0.35, 0.4, 0.5])
    assert np.allclose(p.profile(t), [0, 0, 0.5, 1, 1, 0.5, 0, 0])
    zero = Poke(1, 0.5, 2.0, 0.0, 0.1, 0.1)
    assert not np.any(zero.profile(np.linspace(0, 1, 101)))
    a = simulate(cfg(pokes=(zero,), duration_s=0.2))
    b = simulate(cfg(duration_s=0.2))
    assert not np.any(a.truth["link"]) and np.array_equal(a.q, b.q)


def test_sensor_noise_statistics_and_quantization():
    s = Sensors(torque_noise_Nm=0.02, ft_noise=np.array([0.1, 0.1, 0.01]), encoder_counts=4096, seed=3)
    res = simulate(cfg(sensors=s, duration_s=0.3, base="rigid"))
    d_tau = res.log.tau_Nm - res.tau_Nm
    d_W = res.log.wrench - res.wrench
    assert np.std(d_tau) == pytest.approx(0.02, rel=0.1)
    assert np.std(d_W, axis=0) == pytest.approx([0.1, 0.1, 0.01], rel=0.1)
    step = 2 * np.pi / 4096
    assert np.allclose(res.log.q[:, 3:] / step, np.round(res.log.q[:, 3:] / step), atol=1e-9)
    assert np.abs(res.log.q[:, 3:] - res.q[:, 3:]).max() <= step / 2 + 1e-12
    assert not res.log.floating and np.all(res.log.q[:, :3] == 0)


def test_ground_contact_holds_weight_and_friction_bounds():
    """Foot pressed 5 mm into the floor: at rest W_z + F_n = m g; |F_t| ≤ μ F_n always."""
    robot = paper_leg()
    q0 = np.array([0.6, -1.2])
    foot_z = dyn.contact_point(robot.with_base(True), np.r_[0, 0, 0, q0], 2, 1.0)[1]
    c = cfg(controller=Controller(q0_rad=q0), ground=Ground(height_m=foot_z + 0.005),
            duration_s=0.8, pokes=(Poke(2, 0.5, 3.0, 0.0, 0.4, 0.8),))
    res = simulate(c)
    Fn, Ft = res.ground_force_N[:, 1], res.ground_force_N[:, 0]
    m_tot = robot.base_mass_kg + robot.masses_kg.sum()
    settled = res.t > 0.35
    assert Fn[settled].min() > 1.0
    assert np.all(np.abs(Ft) <= 0.3 * Fn + 1e-9)
    i = np.searchsorted(res.t, 0.38)
    assert res.wrench[i, 1] + Fn[i] == pytest.approx(m_tot * 9.81, rel=2e-3)


def test_batch_rk4_matches_single_runs():
    """The vectorized fixed-step batch gives each member's single-state RK4 trajectory."""
    from estimator.sim import simulate_batch
    from estimator.sim.model import Plant

    c = cfg(integrator="RK4", fixed_step_s=5e-5, duration_s=0.02,
            pokes=(Poke(2, 0.8, 7.0, -np.pi / 3, 0.005, 0.015),))
    y0 = Plant(c).initial_state(3)
    y0[:, 3:5] += np.array([[0.0, 0.0], [0.05, -0.02], [-0.1, 0.03]])
    t, Y = simulate_batch(c, y0)
    assert Y.shape == (len(t), 3, y0.shape[1])
    single = simulate(c)
    assert np.allclose(Y[:, 0, :5], single.q, atol=1e-12)
    assert np.abs(Y[-1, 1, 3:5] - Y[-1, 0, 3:5]).max() > 1e-3        # members differ
