"""The scene pipeline's detector knows the scene's sensor noise (pipeline.scene_noise_model):
σ_τ from the bridge chain (against the chain's own simulated codes), the chi-square default for
`dynamic`, the paper's ε kept for `paper` and for a scene that sets threshold, bad input."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from torquebench import pipeline as P
from torquebench.scenes import load_scene
from userio.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "scenes" / "paper_floating_link2.toml"


def _scene_text(tmp_path, old, new):
    text = DEMO.read_text()
    assert old in text
    p = tmp_path / "scene.toml"
    p.write_text(text.replace(old, new).replace('robot = "paper_leg.toml"',
                                                f'robot = "{ROOT / "robots" / "paper_leg.toml"}"'))
    return p


@pytest.mark.parametrize("gain", [1.0, 1.05])
def test_torque_sigma_matches_the_chains_own_simulated_codes(gain):
    """σ_τ of the noise model = the scatter of the chain's simulated ADC codes at a constant
    torque, read back through the nominal chain (20 000 samples: std known to ±0.5 %, 1σ)."""
    scene = load_scene(DEMO)
    scene = dataclasses.replace(scene, chain=dataclasses.replace(scene.chain, true_gain_factor=gain))
    chain = P.run_sensor_chain(scene, {})
    noise = P.scene_noise_model(scene, chain)
    true = dataclasses.replace(chain, strain_per_Nm=chain.strain_per_Nm * gain)
    codes = true.counts(np.full(20000, 0.3), np.random.default_rng(5))
    tau = chain.torque_from_counts(codes)
    measured = float(np.std(tau))
    assert noise.torque_sigma_Nm[0] == pytest.approx(measured, rel=0.03), (noise.describe(), measured)
    assert "sensor chain" in noise.source and noise.ft_sigma.tolist() == [0.1, 0.1, 0.01]


def test_shipped_scene_defaults_to_chi_square_and_stops_flagging_contact_free_samples():
    """The demo scene without a threshold: `dynamic` flags no contact-free sample (before the poke,
    and from 10/K after its release on; chi-square at 1/h: expected 2.5e-4 flags over ~900
    samples), while the paper's ε = 0.06 (method `paper`, and `dynamic` when the scene sets
    threshold = 0.06) flags more than 1 % of them (measured 20 of 901 at σ_τ = 0.013 N·m)."""
    scene = load_scene(DEMO)
    assert scene.estimator.threshold is None
    arts, _ = P.execute(scene, ["estimates"], None)
    est, t = arts["estimates"], arts["readings"]["t"]
    poke, K = scene.sim.pokes[0], scene.estimator.gain_per_s
    free = (t < poke.t_on_s) | (t >= poke.t_off_s + 10.0 / K)
    assert est["dynamic"].contact[free].sum() == 0
    assert est["paper"].contact[free].mean() > 0.01
    assert "sensor chain" in est["noise_source"]
    old = dataclasses.replace(scene, estimator=dataclasses.replace(scene.estimator, threshold=0.06))
    old_est = P.run_estimates(old, {"readings": arts["readings"], "torques": arts["torques"],
                                    "chain": arts["chain"]})
    assert old_est["dynamic"].contact[free].mean() > 0.01
    assert np.array_equal(old_est["dynamic"].contact, old_est["dynamic"].rnorm > 0.06)


def test_zero_noise_scene_needs_a_threshold(tmp_path):
    p = _scene_text(tmp_path, "ft_noise = [0.1, 0.1, 0.01]", "ft_noise = [0.0, 0.1, 0.01]")
    scene = load_scene(p)
    with pytest.raises(InputError, match="sensors: a zero σ.*set \\[estimator\\] threshold"):
        P.scene_noise_model(scene, P.run_sensor_chain(scene, {}))


@pytest.mark.parametrize("rate, message", [
    ('"2/sample"', "must be in (0, 1) per sample"),
    ('"1/fortnight"', "unknown unit"),
    ('"often"', "expected a rate like"),
])
def test_bad_false_alarm_rate_is_one_line_naming_the_field(tmp_path, rate, message):
    p = _scene_text(tmp_path, 'false_alarm_rate = "1/h"', f"false_alarm_rate = {rate}")
    with pytest.raises(InputError) as exc:
        load_scene(p)
    assert "estimator.false_alarm_rate" in str(exc.value) and message in str(exc.value)
    assert "\n" not in str(exc.value)


def test_simulated_log_noise_is_the_bridge_chain_or_the_gaussian_sigma(tmp_path):
    """The log `simulate` writes (readings="log"): bridge → the chain's noise_std_Nm (what
    estimator.sim.sensors.measure draws through it), gaussian → sensors.torque_noise_Nm."""
    scene = load_scene(DEMO)
    chain = P.run_sensor_chain(scene, {})
    assert P.scene_noise_model(scene, chain, readings="log").torque_sigma_Nm[0] == chain.noise_std_Nm
    p = _scene_text(tmp_path, 'torque_model = "bridge"', 'torque_model = "gaussian"\ntorque_noise_Nm = 0.02\n#')
    gauss = load_scene(p)
    noise = P.scene_noise_model(gauss, None, readings="log")
    assert noise.torque_sigma_Nm[0] == 0.02 and "torque_noise_Nm" in noise.source


def test_quiet_window_states_the_noise_and_a_window_with_the_poke_is_refused(tmp_path):
    """[estimator] quiet_window_s: the detector's covariance comes from that contact-free stretch
    (robust estimate; the way to state a recorded log's noise). Before the poke it flags no
    contact-free sample and still detects the poke; a window holding the poke is one line naming
    the scene's field."""
    p = _scene_text(tmp_path, 'false_alarm_rate = "1/h"',
                    'false_alarm_rate = "1/h"\nquiet_window_s = [0.05, 0.49]')
    scene = load_scene(p)
    assert scene.estimator.quiet_window_s == (0.05, 0.49)
    arts, _ = P.execute(scene, ["estimates"], None)
    est, t = arts["estimates"], arts["readings"]["t"]
    poke, K = scene.sim.pokes[0], scene.estimator.gain_per_s
    free = (t < poke.t_on_s) | (t >= poke.t_off_s + 10.0 / K)
    held = (t > poke.t_on_s + 5.0 / K) & (t < poke.t_off_s)
    assert "quiet window 0.05–0.49 s" in est["noise_source"]
    assert est["dynamic"].contact[free].sum() == 0
    assert est["dynamic"].contact[held].all()

    bad = dataclasses.replace(scene, estimator=dataclasses.replace(scene.estimator,
                                                                   quiet_window_s=(0.05, 0.8)))
    with pytest.raises(InputError) as exc:
        P.run_estimates(bad, {"readings": arts["readings"], "torques": arts["torques"]})
    assert str(exc.value).startswith(f"{p}: estimator.quiet_window_s: the residual changes")
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("window, message", [("[0.4, 0.2]", "t0 < t1"), ("[0.1]", "expected 2 numbers"),
                                              ("[-0.1, 0.2]", "≥ 0")])
def test_bad_quiet_window_is_one_line_naming_the_field(tmp_path, window, message):
    p = _scene_text(tmp_path, 'false_alarm_rate = "1/h"',
                    f'false_alarm_rate = "1/h"\nquiet_window_s = {window}')
    with pytest.raises(InputError) as exc:
        load_scene(p)
    assert "estimator.quiet_window_s" in str(exc.value) and message in str(exc.value)
