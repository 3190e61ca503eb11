"""Localization: exact recovery of static contacts (both methods), flags on singular ones, the
moving leg (dynamic keeps < 5 mm, paper does not), expected contacts (stance foot)."""

import numpy as np
import pytest

from estimator import dynamics as D
from estimator import localization as L
from estimator.detection import isolate
from estimator.estimate import estimate
from estimator.robot import Robot, paper_leg
from estimator.synthetic import moving_leg_poke


def static_contacts(robot, seed=0):
    """A grid of postures × links × α × force directions, τ_ext = Jᵀ F, static τ_meas = G − Jᵀ F."""
    rng = np.random.default_rng(seed)
    N = robot.n_links
    rows = []
    for q1 in np.linspace(-2.6, 2.6, 5):
        for q2 in np.linspace(-2.6, 2.6, 5):
            for link in range(1, N + 1):
                for alpha in (0.1, 0.3, 0.55, 0.8, 0.95):
                    for ang in np.linspace(0, 2 * np.pi, 7, endpoint=False) + 0.1:
                        rows.append((q1, q2, link, alpha, ang))
    rows = np.array(rows)
    T = len(rows)
    q = np.zeros((T, N + 3))
    if robot.floating:
        q[:, :3] = rng.normal(0, [0.01, 0.01, 0.1], (T, 3))
    q[:, 3] = rows[:, 0]
    q[:, 4:] = rows[:, 1:2]
    link = rows[:, 2].astype(int)
    alpha = rows[:, 3]
    F = rng.uniform(1, 8, T)[:, None] * np.stack([np.cos(rows[:, 4]), np.sin(rows[:, 4])], -1)
    full = robot.with_base(True)
    tau_ext = np.zeros((T, N + 3))
    point = np.zeros((T, 2))
    for c in range(1, N + 1):
        m = link == c
        J = D.point_jacobian(full, q[m], c, alpha[m])
        tau_ext[m] = np.einsum("tak,ta->tk", J, F[m])
        point[m] = D.contact_point(full, q[m], c, alpha[m])
    tau_meas = D.gravity_vector(full, q) - tau_ext
    joints, _ = D.forward_kinematics(full, q)
    delta = joints[np.arange(T), link] - joints[np.arange(T), link - 1]
    sin = np.abs(delta[:, 0] * F[:, 1] - delta[:, 1] * F[:, 0]) / np.hypot(*delta.T) / np.hypot(*F.T)
    return dict(q=q, link=link, alpha=alpha, F=F, tau_ext=tau_ext, tau_meas=tau_meas, point=point,
                sin=sin)


def three_link(floating=True):
    return Robot(lengths_m=np.array([0.3, 0.25, 0.2]), com_m=np.array([0.12, 0.1, 0.15]),
                 masses_kg=np.array([1.2, 0.7, 0.4]), inertias_kgm2=np.array([0.01, 0.005, 0.002]),
                 base_mass_kg=2.0, base_inertia_kgm2=0.03, floating=floating)


CASES = [paper_leg(True), paper_leg(False), three_link(True)]


@pytest.mark.parametrize("method", ["dynamic", "paper"])
@pytest.mark.parametrize("robot", CASES, ids=["leg-floating", "leg-fixed", "3link"])
def test_static_contacts_recovered_exactly(robot, method):
    s = static_contacts(robot)
    if method == "dynamic":
        loc = L.localize_dynamic(robot, s["q"], s["tau_ext"])
    else:
        link = isolate(s["tau_ext"][:, 3:], np.full(robot.n_links, 1e-9))
        loc = L.localize_paper(robot, s["q"], np.zeros_like(s["q"]), s["tau_meas"], link)
    good = s["sin"] > 1 / 10                # well away from force ∥ link (flag at 1/20)
    ok = loc.reason == L.OK
    print(f"{robot.name} {method}: {good.sum()} well-conditioned of {len(good)}, "
          f"{ok[good].mean():.3f} answered; flags on the rest: {np.bincount(loc.reason[~good])}")
    assert ok[good].all()
    assert np.all(loc.link[good] == s["link"][good])
    assert np.abs(loc.alpha[good] - s["alpha"][good]).max() < 1e-6
    assert np.abs(loc.force_N[good] - s["F"][good]).max() < 1e-6
    assert np.abs(loc.point_m[good] - s["point"][good]).max() < 1e-6
    # the near-parallel ones are flagged, never a confident number
    singular = s["sin"] < 1 / 25
    assert singular.sum() > 5
    assert np.all(loc.reason[singular] != L.OK)     # parallel_to_link, or ambiguous_link when
    assert np.mean(loc.reason[singular] == L.PARALLEL) > 0.5   # another link fits as well
    assert np.all(np.isnan(loc.alpha[singular]))
    assert np.all(np.isfinite(loc.condition[good]) & (loc.condition[good] <= 10 + 1e-9))


def test_exactly_parallel_and_tiny_forces_are_flagged():
    robot = paper_leg()
    q = np.array([[0, 0, 0, 0.5, -1.0]] * 3)
    joints, _ = D.forward_kinematics(robot, q[0])
    d2 = joints[2] - joints[1]
    F = np.array([2.0 * d2 / np.linalg.norm(d2), [0.01, 0.02], [0.0, 3.0]])
    tau = np.stack([D.point_jacobian(robot, q[0], 2, 0.6).T @ f for f in F])
    loc = L.localize_dynamic(robot, q, tau)
    # a force along link 2 acts anywhere on its line, the knee (link 1, α = 1) included
    assert loc.reason[0] in (L.PARALLEL, L.AMBIGUOUS) and loc.reason[1] == L.SMALL_FORCE
    assert np.isnan(loc.alpha[:2]).all() and abs(loc.alpha[2] - 0.6) < 1e-9
    assert loc.reason[2] == L.OK and loc.reason_names()[1] == "small_force"


def test_contact_off_the_links_is_out_of_bounds():
    """A force whose line of action meets neither link (applied beyond the foot)."""
    robot = paper_leg()
    q = np.array([0, 0, 0, 0.4, -0.8])
    joints, _ = D.forward_kinematics(robot, q)
    J = D.point_jacobian(robot, q, 2, 1.6)       # α = 1.6: a virtual point past the foot
    loc = L.localize_dynamic(robot, q[None], (J.T @ np.array([2.0, 1.0]))[None])
    assert loc.reason[0] == L.OUT_OF_BOUNDS and np.isnan(loc.alpha[0])


def test_moving_leg_dynamic_keeps_under_5mm_paper_does_not():
    robot = paper_leg()
    K = 100.0
    log, truth = moving_leg_poke(robot, duration_s=3.0, frequency_Hz=1.0, t_on_s=0.5,
                                 base_amplitude=(0.01, 0.01, 0.05))
    settled = log.t > 0.5 + 5 / K
    errs = {}
    for method in ("dynamic", "paper"):
        est = estimate(robot, log, method=method, gain_per_s=K, threshold=0.06)
        assert est.contact[settled].all() and not est.contact[log.t < 0.5].any()
        assert np.all(est.link[settled] == 2)
        e = np.hypot(est.px - truth.point_m[:, 0], est.pz - truth.point_m[:, 1])[settled]
        errs[method] = (np.nanmax(e), np.nanmedian(e), np.isfinite(e).mean())
        print(f"moving leg, {method}: position error max {1e3 * errs[method][0]:.2f} mm, "
              f"median {1e3 * errs[method][1]:.2f} mm, answered {errs[method][2]:.3f}")
    assert errs["dynamic"][2] == 1.0 and errs["dynamic"][0] < 0.005
    assert errs["paper"][0] > 0.005


def test_stance_foot_estimated_jointly_not_reported():
    """Paper leg standing on its foot: the foot force is found and is no collision. With a poke
    added the collision is detected; on this 2-link leg (x, z, hip and knee moments: 4 independent
    rows vs 5 unknowns) its location is not identifiable and is flagged, not guessed."""
    robot = paper_leg()
    T = 50
    q = np.tile([0.0, 0.0, 0.0, 0.7, -1.4], (T, 1))
    Jf = D.point_jacobian(robot, q, 2, 1.0)
    F_foot = np.array([0.8, 9.0])
    tau_ext = np.einsum("tak,a->tk", Jf, F_foot)
    unexp, F_est = L.explain_expected(robot, q, tau_ext, [(2, 1.0)])
    assert np.abs(unexp).max() < 1e-12
    np.testing.assert_allclose(F_est[:, 0], np.tile(F_foot, (T, 1)), atol=1e-9)
    J1 = D.point_jacobian(robot, q, 1, 0.5)
    poke = tau_ext + np.einsum("tak,a->tk", J1, np.array([2.0, -1.0]))
    unexp, _ = L.explain_expected(robot, q, poke, [(2, 1.0)])
    assert np.linalg.norm(unexp, axis=1).min() > 0.06                # detected
    loc = L.localize_dynamic(robot, q, poke, expected=[(2, 1.0)])
    assert np.all(loc.reason == L.NOT_IDENTIFIABLE) and np.isnan(loc.alpha).all()


def test_stance_foot_with_poke_on_a_longer_chain():
    """Five links: N + 2 = 7 independent rows ≥ 2 (foot) + 3 (poke) + 2 to tell links apart."""
    robot = Robot(lengths_m=np.full(5, 0.2), com_m=np.full(5, 0.1), masses_kg=np.full(5, 0.3),
                  inertias_kgm2=np.full(5, 0.001), base_mass_kg=1.0, base_inertia_kgm2=0.01)
    rng = np.random.default_rng(4)
    T = 200
    q = np.zeros((T, 8))
    q[:, 3:] = rng.uniform(-1.2, 1.2, (T, 5))
    link = rng.integers(1, 4, T)
    alpha = rng.uniform(0.15, 0.85, T)
    F = rng.normal(0, 3, (T, 2))
    F_foot = rng.normal([0, 10], 2, (T, 2))
    tau = np.einsum("tak,ta->tk", D.point_jacobian(robot, q, 5, 1.0), F_foot)
    for c in (1, 2, 3):
        m = link == c
        tau[m] += np.einsum("tak,ta->tk", D.point_jacobian(robot, q[m], c, alpha[m]), F[m])
    loc = L.localize_dynamic(robot, q, tau, expected=[(5, 1.0)])
    ok = loc.reason == L.OK
    print(f"5-link + foot: {ok.mean():.3f} answered, flags {np.bincount(loc.reason)}")
    assert ok.mean() > 0.8
    assert np.all(loc.link[ok] == link[ok])
    assert np.abs(loc.alpha[ok] - alpha[ok]).max() < 1e-6
    assert np.abs(loc.force_N[ok] - F[ok]).max() < 1e-6
    assert np.abs(loc.expected_force_N[ok, 0] - F_foot[ok]).max() < 1e-6


def test_pipeline_stance_foot_is_not_a_collision(capsys, tmp_path):
    """A standing leg (foot force only): with the foot expected, no collision and the foot force
    is estimated; without it, the foot is (rightly) reported as an unexpected contact."""
    from estimator.log import write_log
    from estimator.synthetic import inverse_dynamics_log
    from torquebench.cli import main

    robot = paper_leg()
    t = np.arange(400) * 1e-3
    q = np.tile([0.0, 0.0, 0.0, 0.6, -1.2], (400, 1))
    z = np.zeros_like(q)
    F_foot = np.array([1.0, 8.0])
    log, _ = inverse_dynamics_log(robot, t, q, z, z, 2, 1.0, F_foot, active=t >= 0.05)
    est = estimate(robot, log, expected_contacts="foot")
    assert not est.contact.any()
    np.testing.assert_allclose(est.expected_force_N[t > 0.3, 0], np.tile(F_foot, ((t > 0.3).sum(), 1)),
                               atol=1e-6)
    plain = estimate(robot, log)
    assert plain.contact[t > 0.1].all() and np.all(plain.link[t > 0.1] == 2)
    np.testing.assert_allclose(plain.alpha[t > 0.3], 1.0, atol=1e-6)
    path = tmp_path / "stand.csv"
    write_log(log, path)
    assert main(["estimate", str(path), "--stance-foot", "--json"]) == 0
    assert '"contact_samples": 0' in capsys.readouterr().out


def test_fast_least_squares_matches_generic_lstsq():
    """The closed-form per-link fit (cofactor solve, any positive definite weight W, e.g. the
    inverse residual covariance) equals numpy lstsq of the whitened problem on noisy residuals,
    where α needs no clipping; costs agree too."""
    robot = Robot(lengths_m=np.array([0.3, 0.25, 0.2]), com_m=np.array([0.12, 0.1, 0.15]),
                  masses_kg=np.array([1.2, 0.7, 0.4]), inertias_kgm2=np.array([0.01, 0.005, 0.002]),
                  base_mass_kg=2.0, base_inertia_kgm2=0.03)
    rng = np.random.default_rng(9)
    T, N = 40, 3
    q = np.zeros((T, 6))
    q[:, :3] = rng.normal(0, 0.05, (T, 3))
    q[:, 3:] = rng.uniform(-2, 2, (T, 3))
    r = rng.normal(0, 1, (T, 6))
    M = rng.normal(size=(6, 6))
    W = M @ M.T + 0.5 * np.eye(6)
    S = np.linalg.cholesky(W).T                   # Sᵀ S = W
    jx, jz = L._joints_link_major(robot, q)
    joints, _ = D.forward_kinematics(robot, q)
    for c in range(1, N + 1):
        alpha_free, alpha, Fx, Fz, cost = L._fit_link(r, np.broadcast_to(W, (T, 6, 6)), jx, jz, c, N)
        A = L._link_columns(joints, c, N)
        for t in range(T):
            x, *_ = np.linalg.lstsq(S @ A[t], S @ r[t], rcond=None)
            e = S @ (r[t] - A[t] @ x)
            if 0 <= alpha_free[t] <= 1:
                np.testing.assert_allclose([Fx[t], Fz[t]], x[:2], atol=1e-10)
                np.testing.assert_allclose(cost[t], np.linalg.norm(e), atol=1e-10)
            else:                              # clipped: cost can only be higher than the free one
                assert cost[t] >= np.linalg.norm(e) - 1e-12
    # the compiled loop is the same solve
    from estimator import compiled

    if compiled.available():
        ref = L.localize_dynamic(robot, q, r, weight=W)
        compiled.ENABLED = False
        try:
            plain = L.localize_dynamic(robot, q, r, weight=W)
        finally:
            compiled.ENABLED = True
        np.testing.assert_allclose(ref.cost, plain.cost, rtol=1e-9)
        same = ref.link == plain.link              # else a tie: α = 1 on a link and 0 on the next
        assert same.mean() > 0.9
        np.testing.assert_allclose(ref.force_N[same], plain.force_N[same], rtol=1e-9, atol=1e-12)


def test_chunked_batches_equal_single_batches():
    """localize_dynamic splits long batches into cache-sized blocks: same answers as small calls."""
    robot = paper_leg()
    rng = np.random.default_rng(1)
    q = rng.normal(size=(20000, 5))
    r = rng.normal(size=(20000, 5))
    whole = L.localize_dynamic(robot, q, r)
    parts = [L.localize_dynamic(robot, q[s:s + 3000], r[s:s + 3000]) for s in range(0, 20000, 3000)]
    for f in ("link", "alpha", "force_N", "point_m", "condition", "reason", "cost"):
        np.testing.assert_array_equal(np.concatenate([getattr(p, f) for p in parts]), getattr(whole, f))
