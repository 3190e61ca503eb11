"""3-D contact episodes on our simulator (estimator.spatial.sim): a poke on the shank, its
release, then a poke on the thigh 30 ms later. The detector's onsets and releases against the
truth (within 2 samples), one interval per poke on the right link, its point (link frame) within
1 mm of the truth with the issue's sensor noise, the same numbers whatever the chunk sizes; and
without the release test the two pokes run together (the residual's decay bridges the gap)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from estimator.spatial.geometry import body_surfaces, surface_point  # noqa: E402
from estimator.spatial.logs import make_noise  # noqa: E402
from estimator.spatial.model import UrdfModel  # noqa: E402
from estimator.spatial.pipeline import SpatialStream, estimate_log  # noqa: E402
from estimator.spatial.robot import load_spatial_robot  # noqa: E402

NOISE = make_noise(0.005, [0.1, 0.01], 3)
TOL_SAMPLES = 2


@pytest.fixture(scope="module")
def episode_log():
    """(model, log, truth): shank 5 N on [0.10, 0.22) s, thigh 6 N on [0.25, 0.38) s, a leg
    tracking a sine on its rig springs, the issue's noise (τ σ 0.005 N·m, F σ 0.1 N, M σ 0.01 N·m)."""
    from estimator.spatial.sim import Poke, SimSpec, simulate

    leg = UrdfModel(load_spatial_robot("robots/quadruped_leg.toml"))
    surfs = body_surfaces(leg.robot, leg.tree)
    p_sh, n_sh = surface_point(surfs[3], "shank", 0.4, 0.5)
    p_th, n_th = surface_point(surfs[2], "thigh", 0.7, 2.5)
    pokes = [Poke("shank", p_sh, -5 * n_sh + np.array([0, 0, 1.0]), 0.10, 0.22),
             Poke("thigh", p_th, -6 * n_th + np.array([1, 0, 0]), 0.25, 0.38)]
    spec = SimSpec(duration_s=0.45, substeps=2, q0_rad=np.array([0.2, 0.6, -1.2]),
                   amplitude_rad=np.array([0.05, 0.1, 0.1]), frequency_Hz=2.0, pokes=pokes,
                   noise=NOISE, seed=11)
    log, truth, _ = simulate(leg.robot, spec)
    return leg, log, truth


def _runs(flag):
    e = np.diff(np.r_[0, np.asarray(flag, int), 0])
    return np.flatnonzero(e == 1), np.flatnonzero(e == -1)       # first sample, one past the last


def test_onsets_releases_and_episodes_on_a_3d_leg(episode_log):
    leg, log, truth = episode_log
    est = estimate_log(leg, [log], 1e-3, noise=NOISE)
    f = est.frame
    on_true = truth.link.to_numpy() != ""
    (s_true, e_true), (s_est, e_est) = _runs(on_true), _runs(f.contact.to_numpy().astype(bool))
    print("onsets", s_est, "truth", s_true, "| releases", e_est, "truth", e_true)
    assert len(s_est) == len(s_true) == 2
    assert np.all((s_est >= s_true) & (s_est <= s_true + TOL_SAMPLES))      # no early alarm
    assert np.all((e_est >= e_true) & (e_est <= e_true + TOL_SAMPLES))
    assert len(est.intervals) == 2
    for iv, s, e in zip(est.intervals, s_true, e_true):
        row = truth.iloc[(s + e) // 2]
        assert iv["link"] == row["link"]
        assert iv["located_fraction"] > 0.95
        err = np.linalg.norm([iv["lx_m"] - row["lx"], iv["ly_m"] - row["ly"], iv["lz_m"] - row["lz"]])
        ferr = np.linalg.norm([iv["Fx_N"] - row["Fx"], iv["Fy_N"] - row["Fy"], iv["Fz_N"] - row["Fz"]])
        print(f"{iv['link']}: point {err * 1e3:.3f} mm, force {ferr:.3f} N")
        assert err < 1e-3
        assert ferr < 0.2
    c = f.contact.to_numpy().astype(bool)
    ok = c & on_true & (f.reason.to_numpy() == "ok")
    assert (f.link.to_numpy()[ok] == truth.link.to_numpy()[ok]).all()
    assert est.info["release_test"].startswith("CUSUM")


def test_episodes_do_not_depend_on_the_chunks(episode_log):
    leg, log, truth = episode_log
    whole = estimate_log(leg, [log], 1e-3, noise=NOISE).frame
    T = len(log.t)
    cuts = [0, 37, 101, 102, 226, 251, 300, T]
    parts = estimate_log(leg, [log.slice(slice(a, b)) for a, b in zip(cuts[:-1], cuts[1:])],
                         1e-3, noise=NOISE).frame
    assert whole.equals(parts)


def test_without_the_release_test_the_two_pokes_run_together(episode_log):
    """What the release test fixes: the first poke's residual decays over ln(‖r‖_w/√h)/K, about
    40 ms, longer than the 30 ms gap, so the stationary chi-square test bridges it."""
    leg, log, truth = episode_log
    st = SpatialStream(leg, 1e-3, noise=NOISE, release_test=False, onset_restart=False)
    st.feed(log)
    est = st.finish()
    s_est, e_est = _runs(est.frame.contact.to_numpy().astype(bool))
    _, e_true = _runs(truth.link.to_numpy() != "")
    assert len(s_est) == 1 and e_est[0] > e_true[0] + 20
