"""The constrained step of the identification (estimator.identification._constrained): the
nearest physically consistent θ in the fit's metric, a semidefinite program over the models'
consistency LMIs, checked against an answer known in closed form and on ill-scaled fits where
a local method (SLSQP on the margins) stopped without a consistent answer."""

from __future__ import annotations

import numpy as np
import pytest

from estimator import identification as ident
from estimator.model import ModelUncertainty

pytest.importorskip("pinocchio")

from estimator.spatial import inertial as si  # noqa: E402
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402

DECLARED = ModelUncertainty(mass_rel=0.05, inertia_rel=0.10, com_m=0.003)


@pytest.fixture(scope="module")
def leg():
    return UrdfModel(load_spatial_robot("robots/quadruped_leg.toml"))


def _frobenius_map(theta0):
    """G with vec_F(J(θ)) = G θ + g (all bodies), so |G (θ − θ_f)|² = Σ_b ‖J_b(θ) − J_b(θ_f)‖²_F."""
    n = theta0.size
    J0 = si.pseudo_inertia(np.zeros(n)).ravel()
    return np.stack([si.pseudo_inertia(e).ravel() - J0 for e in np.eye(n)], axis=1)


def test_the_frobenius_projection_is_eigenvalue_clipping(leg):
    """In the metric ‖J(θ) − J(θ_f)‖_F the nearest J ⪰ 0 is J_f with its negative eigenvalues set
    to 0 (Higham 1988): the fit must land there, to within its certified gap."""
    theta0 = leg.parameters()
    J = si.pseudo_inertia(theta0)
    rng = np.random.default_rng(4)
    for b in range(len(J)):                      # every body loses positivity along a random axis
        lam, V = np.linalg.eigh(J[b])
        v = V @ rng.standard_normal(4)
        v /= np.linalg.norm(v)
        J[b] -= (v @ np.linalg.solve(J[b], v)) ** -1 * 1.5 * np.outer(v, v)
    # θ_f from the damaged J (the map θ → J is linear and one-to-one per body)
    G = _frobenius_map(theta0)
    theta_f = np.linalg.solve(G.T @ G, G.T @ J.ravel())
    assert np.allclose(si.pseudo_inertia(theta_f), J)
    assert leg.consistency_problems(theta_f)
    lam, V = np.linalg.eigh(J)
    J_star = np.einsum("bij,bj,bkj->bik", V, np.clip(lam, 0, None), V)
    theta_star = np.linalg.solve(G.T @ G, G.T @ J_star.ravel())
    H = G.T @ G
    P0 = leg.parameter_covariance(DECLARED)
    theta, active = ident._constrained(leg, H, theta_f, theta0, P0)
    assert leg.consistency_problems(theta) == []
    q = lambda t: (t - theta_f) @ H @ (t - theta_f)                            # noqa: E731
    gap = 1e-10 * q(theta0)
    assert q(theta_star) <= q(theta) <= q(theta_star) + 2 * gap + 1e-12 * q(theta_star)
    # strong convexity: ‖θ − θ*‖²_H ≤ q(θ) − q(θ*) (θ* optimal, the set convex)
    d = theta - theta_star
    assert d @ H @ d <= q(theta) - q(theta_star) + 2 * gap + 1e-12 * q(theta_star)
    assert len(active) >= len(J)                 # each body ends on its boundary


@pytest.mark.parametrize("seed", range(6))
def test_ill_scaled_fits_reach_a_consistent_optimum(leg, seed):
    """Information scaled over orders of magnitude (as a short, poorly exciting log gives) and an
    unconstrained optimum with every body inconsistent: a consistent θ is found, and no consistent
    θ drawn around it, nor the file's own θ, fits better (the first-order optimality condition of
    a convex problem, ∇q(θ)ᵀ(θ' − θ) ≥ 0 for consistent θ', checked on draws)."""
    rng = np.random.default_rng(seed)
    theta0 = leg.parameters()
    P0 = leg.parameter_covariance(DECLARED)
    sig = np.sqrt(np.diag(P0))
    n = theta0.size
    A = rng.standard_normal((3 * n, n)) * rng.lognormal(0.0, 2.0, n)
    H = (A.T @ A) / np.outer(sig, sig) * 1e2 + np.linalg.inv(P0)
    theta_f = theta0 + 4 * sig * rng.standard_normal(n)
    if not leg.consistency_problems(theta_f):
        pytest.skip("this draw is consistent")
    theta, _ = ident._constrained(leg, H, theta_f, theta0, P0)
    assert leg.consistency_problems(theta) == []
    grad = 2 * H @ (theta - theta_f)
    q = lambda t: (t - theta_f) @ H @ (t - theta_f)                            # noqa: E731
    tol = 1e-8 * q(theta0)
    sizes = leg.body_sizes_m
    wide = ModelUncertainty(mass_rel=0.3, inertia_rel=0.5, com_m=0.02)
    others = si.draw(theta, sizes, wide, rng, 400)
    others = [o for o in others if not leg.consistency_problems(o)]
    assert len(others) > 300
    assert all(grad @ (o - theta) >= -tol for o in others)
    assert q(theta) <= q(theta0)
