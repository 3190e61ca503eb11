"""The paper leg written as a URDF (robots/paper_leg_urdf.toml: joints about −y) reproduces the
planar estimator on a planar log (examples/leg_poke: an independent MuJoCo run of the paper
leg) converted to the 3-D contract: the residual rows, the whitened statistic (with the release
test's tail subtraction), the contact flags and, on the observer restarted at each onset, the
contact link, point and force — to round-off."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from estimator.log_reader import read_log  # noqa: E402
from estimator.noise import paper_leg_noise  # noqa: E402
from estimator.estimate import estimate  # noqa: E402
from estimator.robot import paper_leg  # noqa: E402
from estimator.spatial.logs import SpatialLog, make_noise  # noqa: E402
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.pipeline import estimate_log  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402


def to_3d(log):
    """A planar log [x, z, θ, q…] (angles about −y) in the 3-D column contract: y = 0, the
    quaternion of θ about −y, ṗ = (ẋ, 0, ż), ω = (0, −θ̇, 0) (base frame), the wrench in the base
    (= sensor) frame: f = Rᵀ(Fx, 0, Fz), m = (0, −My, 0)."""
    T = len(log.t)
    th = log.q[:, 2]
    q = np.zeros((T, 7 + log.n_links))
    q[:, 0], q[:, 2] = log.q[:, 0], log.q[:, 1]
    q[:, 4], q[:, 6] = -np.sin(th / 2), np.cos(th / 2)
    q[:, 7:] = log.q[:, 3:]
    v = np.zeros((T, 6 + log.n_links))
    v[:, 0], v[:, 2], v[:, 4] = log.dq[:, 0], log.dq[:, 1], -log.dq[:, 2]
    v[:, 6:] = log.dq[:, 3:]
    c, s = np.cos(th), np.sin(th)            # R = rotation by θ about −y: R x̂ = (c, 0, s)
    Fx, Fz, My = log.wrench.T
    w = np.zeros((T, 6))
    w[:, 0] = c * Fx + s * Fz
    w[:, 2] = -s * Fx + c * Fz
    w[:, 4] = -My
    return SpatialLog(t=log.t, q=q, v=v, tau_Nm=log.tau_Nm, wrench=w)


@pytest.fixture(scope="module")
def both():
    planar_log = read_log("examples/leg_poke/leg_poke.csv", paper_leg())
    model = UrdfModel(load_spatial_robot("robots/paper_leg_urdf.toml"))
    log3 = to_3d(planar_log)
    # both with their release test and onset restart (estimator.release, estimator.onset), both
    # fits weighted by the noise, as the planar dynamic method is
    planar = estimate(paper_leg(), planar_log, noise=paper_leg_noise())
    noise = make_noise(0.005, [0.1, 0.1, 0.1, 0.01, 0.01, 0.01], 2)
    spatial = estimate_log(model, [log3], planar_log.period_s, noise=noise, weighting="whitened")
    return planar, spatial, model


def test_residual_rows_match(both):
    planar, spatial, _ = both
    r2, r3 = planar.residual, spatial.residual
    mapped = np.c_[r3[:, 0], r3[:, 2], -r3[:, 4], r3[:, 6:]]
    scale = np.abs(r2).max()
    assert np.abs(mapped - r2).max() < 1e-9 * scale
    assert np.abs(r3[:, [1, 3, 5]]).max() < 1e-9 * scale            # nothing out of the plane
    print(f"residual: max |Δr| / max |r| = {np.abs(mapped - r2).max() / scale:.2e}")


def test_whitened_statistic_matches(both):
    planar, spatial, _ = both
    assert np.allclose(spatial.frame.rnorm.to_numpy(), planar.rnorm, rtol=1e-7, atol=1e-9)


def test_contact_flags_match(both):
    """The same onsets and the same releases (the release test's CUSUM on the same drive)."""
    planar, spatial, _ = both
    assert (spatial.frame.contact.to_numpy().astype(bool) == planar.contact).all()
    assert spatial.info["release_test"].startswith("CUSUM")


def test_localization_matches_planar(both):
    planar, spatial, _ = both
    f = spatial.frame
    both_on = planar.contact & f.contact.to_numpy().astype(bool)
    ok = both_on & (planar.reason_names() == "ok") & (f.reason.to_numpy() == "no_geometry")
    assert ok.sum() > 400                                             # the poke's 500 ms
    names = np.array(["", "link1", "link2"], dtype=object)
    assert (f.link.to_numpy()[ok] == names[planar.link[ok]]).all()
    p3 = f[["px", "py", "pz"]].to_numpy()[ok]
    assert np.abs(p3[:, 0] - planar.px[ok]).max() < 1e-9
    assert np.abs(p3[:, 2] - planar.pz[ok]).max() < 1e-9
    assert np.abs(p3[:, 1]).max() < 1e-12
    F3 = f[["Fx", "Fy", "Fz"]].to_numpy()[ok]
    assert np.abs(F3[:, 0] - planar.Fx[ok]).max() < 1e-8 and np.abs(F3[:, 2] - planar.Fz[ok]).max() < 1e-8
    print(f"{ok.sum()} samples: |Δp| ≤ {max(np.abs(p3[:, 0] - planar.px[ok]).max(), np.abs(p3[:, 2] - planar.pz[ok]).max()):.2e} m, "
          f"|ΔF| ≤ {max(np.abs(F3[:, 0] - planar.Fx[ok]).max(), np.abs(F3[:, 2] - planar.Fz[ok]).max()):.2e} N")
