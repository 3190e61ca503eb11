"""Stiff and extreme cases of the simulator: refused up front or while running, never silent."""

from dataclasses import replace

import numpy as np
import pytest

from userio.errors import InputError
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
    # refused by the up-front probe (estimated run time) or by the watchdog while running,
    # depending on the machine's speed: either way one line naming the limit and the fastest pole
    with pytest.raises(InputError, match=r"limit 10 s .*fastest pole 5.4\d?e\+07 .*--max-run-time"):
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


@pytest.mark.parametrize("k", [5e5, 5e6, 5e7])
def test_stiff_mount_implicit_accurate_rk4_refused_with_pole_reported(k):
    """Base mount k from 5e5 to 5e7 N/m: BDF matches a tight Radau reference; RK4 at the default
    step is refused up front when |R(hλ)| > 1, naming the fastest pole."""
    from estimator.sim import check_stability

    K = np.array([k, k, k / 100])
    D = 2 * 0.3 * np.sqrt(K * np.array([3.0, 3.0, 0.05]))
    cfg = replace(_moving(duration_s=0.03), base="fixed", mount_stiffness=K, mount_damping=D)
    stab = check_stability(cfg)
    res = simulate(replace(cfg, integrator="BDF", rtol=1e-8, atol=1e-10))
    ref = simulate(replace(cfg, integrator="Radau", rtol=1e-11, atol=1e-13), estimate=False)
    assert np.max(np.abs(res.q - ref.q)) < 1e-6
    assert res.stats["stiffness_ratio"] == pytest.approx(stab.stiffness_ratio)
    h = 5e-5
    if 2.78 / stab.fastest_pole_per_s < h:
        with pytest.raises(InputError, match="RK4 .* unstable .*fastest pole"):
            simulate(replace(cfg, integrator="RK4", fixed_step_s=h))


@pytest.mark.parametrize("k_dt", [0.1, 1.0, 10.0, 100.0])
def test_observer_gain_times_step_stays_stable_and_naive_euler_would_not(k_dt):
    """Exact discretization: a = e^{-KΔt} ∈ (0, 1) for any KΔt. Naive Euler a = 1 − KΔt has
    |a| > 1 (divergent) for KΔt > 2, so the explicit form is refused there."""
    from estimator.observer import coefficients

    K = np.array([k_dt, k_dt])
    a, b = coefficients(K, 1.0, "exact")
    assert np.all((0 <= a) & (a < 1)) and np.allclose(a + b, 1.0)
    naive = 1.0 - k_dt
    if k_dt >= 2.0:
        assert abs(naive) > 1.0
        with pytest.raises(InputError, match="unstable for K·Δt ≥ 2"):
            coefficients(K, 1.0, "explicit")
    else:
        assert np.allclose(coefficients(K, 1.0, "explicit")[0], naive)
    # the exact recurrence on a unit step input settles to 1 without overshoot
    r, out = 0.0, []
    for _ in range(200):
        r = a[0] * r + b[0] * 1.0
        out.append(r)
    assert max(out) <= 1.0 + 1e-12 and abs(out[-1] - 1.0) < 1e-6 * max(1, 1 / k_dt) + np.exp(-200 * k_dt)


def test_stability_report_rows_name_existing_tests_and_build(tmp_path):
    from torquebench.io import REPO_ROOT
    from torquebench.reports import stability

    assert stability.missing_tests(REPO_ROOT) == []
    assert len(stability.ROWS) >= 20
    (md,) = stability.build(tmp_path)
    text = md.read_text()
    assert text.count("| `tests/") == len(stability.ROWS)
