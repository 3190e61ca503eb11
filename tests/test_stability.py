"""Stiff and extreme cases of the simulator: refused up front or while running, never silent."""

from dataclasses import replace

import numpy as np
import pytest

from estimator.errors import InputError
from estimator.sim import simulate
from torquebench.cli import main
from torquebench.scenes import load_scene

MOVING = "scenes/moving_leg.toml"


def _moving(**kw):
    sc = load_scene(MOVING).sim
    ctrl = {k: kw.pop(k) for k in ("kp",) if k in kw}
    if ctrl:
        sc = replace(sc, controller=replace(sc.controller, **ctrl))
    return replace(sc, **kw)


def test_stiff_servo_explicit_integrator_refused_up_front_with_stiffness_ratio():
    with pytest.raises(InputError, match=r"explicit RK45 .*stiffness ratio .*Radau or BDF"):
        simulate(_moving(kp=1e12, integrator="RK45"), max_run_time_s=600)


def test_stiff_servo_kp_1e12_implicit_is_stopped_at_the_run_time_limit():
    """Tried as a new user would: kp = 1e12 on moving_leg ran silently for minutes; now it stops."""
    with pytest.raises(InputError, match=r"BDF reached t = .* > the limit 10 s .*--max-run-time"):
        simulate(_moving(kp=1e12, duration_s=0.5), max_run_time_s=10)


def test_huge_duration_refused_before_integrating(tmp_path, capsys):
    code = main(["simulate", MOVING, "--out", str(tmp_path / "x.csv"), "--duration", "1e9"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "log samples" in err[0]
    assert not (tmp_path / "x.csv").exists()


def test_integration_error_estimate_brackets_the_true_error():
    """q_rad_error_estimate (10x-tighter rerun of the first window) against a Radau 1e-12 reference."""
    cfg = _moving(duration_s=0.05, integrator="RK45", rtol=1e-4, atol=1e-6)
    res = simulate(cfg)
    ref = simulate(replace(cfg, integrator="Radau", rtol=1e-11, atol=1e-13), estimate=False)
    n = ref.q.shape[1]
    true_err = np.max(np.abs(res.q[:, :n] - ref.q[:, :n]))
    est = res.stats["q_rad_error_estimate"]
    assert "tighter" in res.stats["q_rad_error_method"]
    assert 0.1 * true_err <= est <= 10 * true_err, (est, true_err)


def test_rk4_error_estimate_is_richardson_and_close():
    cfg = _moving(duration_s=0.05, integrator="RK4", fixed_step_s=5e-5)
    res = simulate(cfg)
    ref = simulate(replace(cfg, integrator="Radau", rtol=1e-11, atol=1e-13), estimate=False)
    true_err = np.max(np.abs(res.q - ref.q))
    est = res.stats["q_rad_error_estimate"]
    assert "Richardson" in res.stats["q_rad_error_method"]
    assert 0.3 * true_err <= est <= 3 * true_err, (est, true_err)
