"""Noise of the measured base state (orientation, ṗ, ω) in the 3-D residual's covariance
(estimator.spatial.noise): its Jacobians against pinocchio (the mass matrix, the gravity
derivatives) and the FT force row's turn, the base position entering nothing, and a Monte Carlo
on a held leg: the predicted covariance matches the sample one, the chi-square detector holds
its stated rate with the term and flags a large share of the samples without it."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from estimator.spatial.logs import make_noise  # noqa: E402
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.noise import base_jacobians, quat_times_exp, residual_covariance  # noqa: E402
from estimator.spatial.observer import residual  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402
from estimator.spatial.tree import quat_matrix  # noqa: E402


@pytest.fixture(scope="module")
def leg():
    return UrdfModel(load_spatial_robot("robots/quadruped_leg.toml"))


def _posture(rng):
    q = np.r_[rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.2, 1.0, 0.3, 0.7, -1.1]
    q[3:7] /= np.linalg.norm(q[3:7])
    return q


def _skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def test_base_jacobians_against_pinocchio(leg):
    import pinocchio as pin

    rng = np.random.default_rng(4)
    q = _posture(rng)
    v = rng.normal(size=9)
    JP, Ju = base_jacobians(leg, q[None], v[None], wrench=np.zeros((1, 6)))
    model = leg.robot.model
    data = model.createData()
    R = quat_matrix(q[3:7][None])[0]
    D = np.eye(9)
    D[:3, :3] = R                                 # ours = D · pinocchio's (force rows to the world)
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    assert np.allclose(JP[0][:, 3:], (D @ M @ D.T)[:, :6], rtol=1e-6, atol=1e-8)
    # at rest u = −G: its orientation derivative against pinocchio's gravity derivatives (local
    # frame δθ, as ours); the world force row −M g does not turn
    JP0, Ju0 = base_jacobians(leg, q[None], np.zeros((1, 9)), wrench=np.zeros((1, 6)))
    dG = pin.computeGeneralizedGravityDerivatives(model, data, q)
    g = pin.computeGeneralizedGravity(model, data, q)
    assert np.abs(Ju0[0][:3, :3]).max() < 1e-6
    assert np.abs(R @ (dG[:3, 3:6] - _skew(g[:3]))).max() < 1e-9         # pinocchio agrees
    assert np.allclose(Ju0[0][3:, :3], -dG[3:, 3:6], rtol=1e-6, atol=1e-7)
    assert np.abs(JP0[0][:, :3]).max() < 1e-9                            # P = M v = 0 at rest
    # the FT force row turns with the orientation: ∂(R f_b)/∂δθ = −R [f_b]×
    w = rng.normal(size=(1, 6)) * [5, 5, 30, 1, 1, 1]
    _, Juw = base_jacobians(leg, q[None], np.zeros((1, 9)), wrench=w)
    Rbs, _ = leg.robot.ft_placement()
    f_b = Rbs @ w[0, :3]
    assert np.allclose((Juw - Ju0)[0][:3, :3], -R @ _skew(f_b), atol=1e-6)
    assert np.abs((Juw - Ju0)[0][3:, :3]).max() < 1e-6
    # the base position enters nothing
    q2 = q.copy()
    q2[:3] += [0.3, -0.2, 0.5]
    P1, u1 = leg.momentum_terms(q[None], v[None], np.zeros((1, 9)))
    P2, u2 = leg.momentum_terms(q2[None], v[None], np.zeros((1, 9)))
    assert np.allclose(P1, P2, atol=1e-12) and np.allclose(u1, u2, atol=1e-12)


def test_base_jacobians_of_a_moving_leg_against_pinocchio_forward_dynamics(leg):
    """At v ≠ 0 the Coriolis part Cᵀv turns with the orientation and the twist too. Reference:
    u = Ṗ at τ = 0 along pinocchio's forward dynamics (aba; our P is pinocchio's crba, above),
    Ṗ by a central difference along the motion, then ∂u/∂x by central differences in x."""
    import pinocchio as pin

    model = leg.robot.model
    data = model.createData()
    rng = np.random.default_rng(4)
    q = _posture(rng)
    v = rng.normal(size=9)

    def u_ref(q, v, eps=1e-5):
        R = quat_matrix(q[3:7][None])[0]
        vp = v.copy()
        vp[:3] = R.T @ v[:3]                      # pinocchio's free flyer: base-frame velocity
        ap = pin.aba(model, data, q, vp, np.zeros(9))
        a = ap.copy()
        a[:3] = R @ (ap[:3] + np.cross(vp[3:6], vp[:3]))                 # p̈ in the world
        P = [leg.momentum_terms(pin.integrate(model, q, s * eps * vp)[None], (v + s * eps * a)[None],
                                np.zeros((1, 9)))[0][0] for s in (1, -1)]
        return (P[0] - P[1]) / (2 * eps)

    _, u = leg.momentum_terms(q[None], v[None], np.zeros((1, 9)))
    assert np.abs(u[0] - u_ref(q, v)).max() < 1e-8 * np.abs(u).max()   # the identity itself
    h = 1e-4
    ref = np.zeros((9, 9))
    for i in range(3):
        e = np.eye(3)[i] * h
        qp, qm = q.copy(), q.copy()
        qp[3:7] = quat_times_exp(q[3:7][None], e[None])[0]
        qm[3:7] = quat_times_exp(q[3:7][None], -e[None])[0]
        ref[:, i] = (u_ref(qp, v) - u_ref(qm, v)) / (2 * h)
        for col, k in ((3 + i, i), (6 + i, 3 + i)):                      # ṗ (world), ω (base)
            vp, vm = v.copy(), v.copy()
            vp[k] += h
            vm[k] -= h
            ref[:, col] = (u_ref(q, vp) - u_ref(q, vm)) / (2 * h)
    _, Ju = base_jacobians(leg, q[None], v[None], wrench=np.zeros((1, 6)))
    _, Ju0 = base_jacobians(leg, q[None], np.zeros((1, 9)), wrench=np.zeros((1, 6)))
    assert np.abs((Ju - Ju0)[0]).max() > 0.1 * np.abs(ref).max()        # the motion matters here
    assert np.abs(Ju[0] - ref).max() < 1e-5 * np.abs(ref).max()


def _held_log(leg, noise, T, seed):
    """A held posture read with white noise on every channel (FT, torques, base state)."""
    rng = np.random.default_rng(seed)
    q0 = _posture(np.random.default_rng(8))
    _, u0 = leg.momentum_terms(q0[None], np.zeros((1, 9)), np.zeros((1, 9)))
    w0 = leg.ft_from_base_rows(q0[None], -u0[:, :6])
    e = rng.normal(size=(T, 9)) * noise.base_sigma
    q = np.tile(q0, (T, 1))
    q[:, 3:7] = quat_times_exp(q[:, 3:7], e[:, :3])
    v = np.zeros((T, 9))
    v[:, :6] = e[:, 3:]
    wrench = w0 + rng.normal(size=(T, 6)) * noise.ft_sigma
    tau_j = -u0[:, 6:] + rng.normal(size=(T, 3)) * noise.torque_sigma_Nm
    return q0, q, v, wrench, tau_j


BASE = dict(base_orientation_sigma=2e-3, base_velocity_sigma=2e-4, base_rate_sigma=2e-3)


@pytest.mark.slow
def test_covariance_and_false_alarms_with_base_noise(leg):
    from scipy.special import chdtri

    from estimator.spatial.logs import SpatialLog
    from estimator.spatial.pipeline import estimate_log

    noise = make_noise(0.005, [0.1, 0.01], 3, **BASE)
    T = 40000
    q0, q, v, wrench, tau_j = _held_log(leg, noise, T, seed=5)
    t = np.arange(T) * 1e-3
    tau = np.concatenate([leg.base_rows_from_ft(q, wrench), tau_j], axis=1)
    r = residual(leg, t, q, v, tau)[200:]
    C = np.cov(r.T)
    R = residual_covariance(leg, q0[None], np.zeros((1, 9)), noise, 100.0, 1e-3)[0]
    R_ft = residual_covariance(leg, q0[None], np.zeros((1, 9)), make_noise(0.005, [0.1, 0.01], 3),
                               100.0, 1e-3)[0]
    print("σ ratio base-noise term included / sensors only:", np.round(np.sqrt(np.diag(R) / np.diag(R_ft)), 2))
    assert np.diag(R)[:3].min() > 2 * np.diag(R_ft)[:3].max()     # the term matters here
    assert np.allclose(np.diag(C), np.diag(R), rtol=0.05)
    d = np.sqrt(np.diag(R))
    assert np.abs(C / np.outer(d, d) - R / np.outer(d, d)).max() < 0.05
    # the detector, one false alarm per hour, with and without the term
    log = SpatialLog(t=t, q=q, v=v, tau_Nm=tau_j, wrench=wrench)
    n_dof = 9
    out = {}
    for name, nz in (("with", noise), ("without", make_noise(0.005, [0.1, 0.01], 3))):
        f = estimate_log(leg, [log], 1e-3, noise=nz).frame.iloc[200:]
        s = f.rnorm.to_numpy() ** 2
        out[name] = (f.contact.to_numpy().mean(), (s > chdtri(n_dof, 0.01)).mean())
        print(f"{name} the term: flagged {out[name][0]:.2e} (stated {T / 3.6e6:.1e} samples), "
              f"above the 1 % point {out[name][1]:.4f}")
    N = T - 200
    assert out["with"][0] * N <= 2              # expected 0.011 alarms in 11 s at one per hour
    assert abs(out["with"][1] - 0.01) < 4 * np.sqrt(0.01 * 0.99 / N) + 0.002   # binomial (the
    # samples are correlated by the filter: the margin allows for it)
    assert out["without"][0] > 0.1


def test_noise_side_file_carries_the_base_noise(leg, tmp_path):
    from estimator.spatial.logs import noise_text, read_noise
    from userio.errors import InputError

    noise = make_noise(0.005, [0.1, 0.01], 3, base_orientation_sigma=[1e-3, 2e-3, 3e-3],
                       base_velocity_sigma=2e-4, base_rate_sigma=0.01)
    log = tmp_path / "leg.csv"
    log.write_text("t\n")
    (tmp_path / "leg.noise.toml").write_text(noise_text(noise))
    back = read_noise(log, leg.robot)
    assert np.allclose(back.base_sigma, noise.base_sigma)
    (tmp_path / "leg.noise.toml").write_text(noise_text(noise).replace("[0.01, 0.01, 0.01]", "[0.01, -1]"))
    with pytest.raises(InputError, match="base_rate_sigma_rad_per_s"):
        read_noise(log, leg.robot)
