"""bridge: Wheatstone bridge, ADC/ENOB, noise budget and eq. 11 against hand-derived values."""

import math
import warnings
from fractions import Fraction

import numpy as np
import pytest
from scipy.integrate import quad

from bridge import adc
from bridge.budget import (amplifier_noise_rms_V, eps_min_eq11, johnson_density_V_per_rtHz,
                           min_detectable_strain, min_detectable_torque_Nm, noise_budget)
from bridge.config import SensorConfig, load_sensor_config, sensor_config_from_dict
from bridge.wheatstone import BridgeInverseWarning, StrainRangeWarning
from userio.errors import InputError
from bridge.wheatstone import (ARRANGEMENTS, effective_gauge_factor, gauge_strains,
                               linear_output_ratio, output_ratio, pattern, ratio_from_strain,
                               self_heating_W, sensitivity_factor, strain_from_ratio)

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- exact reference (rationals)
def _ratio_fraction(strains, arrangement, gf=2, r=1000, r_lead=0):
    """R1/(R1+R2) − R4/(R3+R4) in exact rational arithmetic, arms built from resistances."""
    k, arms = ARRANGEMENTS[arrangement]
    r0 = Fraction(r) + Fraction(r_lead)
    arm_r = [r0, r0, r0, r0]                      # completion resistors balance the bridge
    for j, arm in enumerate(arms):
        arm_r[arm] = Fraction(r) * (1 + Fraction(gf) * Fraction(float(strains[j]))) + Fraction(r_lead)
    r1, r2, r3, r4 = arm_r
    return r1 / (r1 + r2) - r4 / (r3 + r4)


@pytest.mark.parametrize("arrangement", list(ARRANGEMENTS))
def test_output_ratio_matches_exact_rational_reference(arrangement):
    rng = np.random.default_rng(1)
    k = ARRANGEMENTS[arrangement][0]
    for scale in (1e-9, 1e-6, 1e-3, 2e-2):
        eps = rng.uniform(-scale, scale, size=(5, k))
        got = output_ratio(eps, arrangement, 2.0, 1000.0, 7.5)
        for i in range(5):
            ref = _ratio_fraction(eps[i], arrangement, 2, 1000, Fraction(15, 2))
            assert got[i] == pytest.approx(float(ref), rel=1e-13, abs=1e-300)


def test_full_bridge_1000_microstrain_is_10_mV():
    v = 5.0 * output_ratio([1e-3, -1e-3, 1e-3, -1e-3], "full_bending", 2.0)
    assert v == pytest.approx(10e-3, rel=1e-14)
    assert 5.0 * linear_output_ratio([1e-3, -1e-3, 1e-3, -1e-3]) == pytest.approx(10e-3, rel=1e-14)


def test_quarter_bridge_nonlinearity_at_1000_microstrain():
    exact = output_ratio([[1e-3]], "quarter")[0]
    lin = linear_output_ratio([[1e-3]], "quarter")[0]
    assert lin == pytest.approx(2.0 * 1e-3 / 4, rel=1e-15)          # eq. 10
    # hand: exact/linear = 2/(2 + GF ε) = 1/1.001 → −0.0999 %
    assert exact / lin - 1 == pytest.approx(-0.001 / 1.001, rel=1e-9)
    assert round((exact / lin - 1) * 100, 2) == -0.10


def test_linearization_and_sensitivity_factors():
    expect = {"quarter": 0.25, "half_bending": 0.5, "half_poisson": 1.3 / 4, "full_bending": 1.0,
              "full_poisson": 1.3 / 2, "full_poisson_iii": 1.3 / 2}
    for a, s in expect.items():
        assert sensitivity_factor(a, 0.3) == pytest.approx(s, rel=1e-15)
        eps = gauge_strains(1e-7, a, 0.3)
        assert linear_output_ratio(eps, a) == pytest.approx(s * 2.0 * 1e-7, rel=1e-12)
        # tiny strain: exact → linear
        assert output_ratio(eps, a) == pytest.approx(s * 2.0 * 1e-7, rel=1e-6)


def test_lead_resistance_desensitizes():
    assert effective_gauge_factor(2.0, 1000.0, 10.0) == pytest.approx(2.0 * 1000 / 1010)
    v = output_ratio([1e-3, -1e-3, 1e-3, -1e-3], "full_bending", 2.0, 1000.0, 10.0)
    assert v == pytest.approx(2.0 * 1e-3 * 1000 / 1010, rel=1e-14)


@pytest.mark.parametrize("arrangement", list(ARRANGEMENTS))
def test_round_trip_strain_ratio_strain(arrangement):
    eps = np.concatenate([np.geomspace(1e-9, 2.5e-2, 60), -np.geomspace(1e-9, 2.5e-2, 60), [0.0]])
    kw = dict(gauge_factor=2.1, gauge_resistance_ohm=350.0, lead_resistance_ohm=1.3,
              poisson_ratio=0.33)
    v = ratio_from_strain(eps, arrangement, **kw)
    # closed form = general arm formula applied to the pattern
    v_general = output_ratio(gauge_strains(eps, arrangement, 0.33), arrangement, 2.1, 350.0, 1.3)
    np.testing.assert_allclose(v, v_general, rtol=1e-14, atol=0)
    back = strain_from_ratio(v, arrangement, **kw)
    np.testing.assert_allclose(back, eps, rtol=1e-12, atol=0)
    # 1e-9 strain in float64: the ratio itself is accurate (no cancellation)
    assert strain_from_ratio(ratio_from_strain(1e-9, arrangement), arrangement) == \
        pytest.approx(1e-9, rel=1e-14)


def test_quarter_inverse_near_singularity():
    # v → 1/2 is the pole of y = 4v/(1 − 2v) (R1 → ∞)
    v = np.array([0.5 - 1e-6, 0.49, -0.49])
    eps = strain_from_ratio(v, "quarter")
    assert np.all(np.isfinite(eps))
    np.testing.assert_allclose(ratio_from_strain(eps, "quarter"), v, rtol=1e-10)
    with pytest.warns(BridgeInverseWarning):
        bad = strain_from_ratio(np.array([0.5, 0.7, -0.5, 0.1]), "quarter")
    assert np.isnan(bad[:3]).all() and np.isfinite(bad[3])
    with pytest.warns(BridgeInverseWarning):
        assert np.isnan(strain_from_ratio(2.0, "full_poisson_iii"))


def test_strain_beyond_gauge_range_warns_and_nonpositive_resistance_raises():
    with pytest.warns(StrainRangeWarning):
        output_ratio([[0.05]], "quarter")
    with pytest.raises(InputError, match="non-positive resistance"):
        output_ratio([[-0.6]], "quarter", strain_limit=None)
    with pytest.raises(InputError, match="shape"):
        output_ratio([1e-3, 1e-3], "full_bending")
    with pytest.raises(InputError, match="arrangement"):
        output_ratio([1e-3], "eighth")
    with pytest.raises(InputError, match="gauge_resistance_ohm"):
        output_ratio([[1e-3]], "quarter", gauge_resistance_ohm=-1.0)
    with pytest.raises(InputError, match="gauge_factor"):
        output_ratio([[1e-3]], "quarter", gauge_factor=0.0)


def test_self_heating():
    assert self_heating_W(5.0, 1000.0) == pytest.approx(6.25e-3)


# ---------------------------------------------------------------- ADC / ENOB
def test_enob_definitions_and_conversion():
    fsr = 5.0
    assert adc.noise_rms_from_enob(16, fsr, "ti") == pytest.approx(5.0 / 65536)
    # ieee: full-scale sine rms FSR/(2√2), SINAD = 6.02·16 + 1.76
    sigma = adc.noise_rms_from_enob(16, fsr, "ieee")
    assert 20 * math.log10(fsr / (2 * math.sqrt(2)) / sigma) == pytest.approx(6.02 * 16 + 1.76)
    d = adc.convert_enob(16.0, "ti", "ieee") - 16.0
    assert d == pytest.approx((20 * math.log10(2) * 16 - 20 * math.log10(2 * math.sqrt(2)) - 1.76)
                              / 6.02 - 16, rel=1e-12)
    assert -1.81 < d < -1.77                                        # "≈ 1.8 bits"
    assert adc.convert_enob(adc.convert_enob(15.3, "ieee", "ti"), "ti", "ieee") == \
        pytest.approx(15.3, rel=1e-13)
    assert adc.noise_free_bits(5.0 / 65536, 5.0) == pytest.approx(16 - math.log2(6.6))
    with pytest.raises(InputError, match="enob_definition"):
        adc.noise_rms_from_enob(16, fsr, "bogus")


def test_quantize_and_saturate():
    lsb = adc.lsb_V(8, 1.0)
    codes, sat = adc.quantize([0.0, 3.4 * lsb, -1.0, 1.0, 5.0], 8, 1.0)
    assert codes.tolist() == [0, 3, -128, 127, 127]
    assert sat.tolist() == [False, False, False, True, True]


# ---------------------------------------------------------------- eq. 11 and the budget
def test_eq11_paper_numbers():
    assert eps_min_eq11(24) == pytest.approx(5.96e-8, rel=1e-3)
    assert eps_min_eq11(16) == pytest.approx(1.53e-5, rel=3e-3)
    assert eps_min_eq11(24) == 2.0 ** -24                      # 4·2.5/(2·5·2^24) exactly
    cfg = SensorConfig()
    assert min_detectable_strain(cfg, arrangement="quarter") == pytest.approx(eps_min_eq11(24),
                                                                                rel=1e-15)
    assert min_detectable_strain(cfg, arrangement="quarter", n_bits=16) == \
        pytest.approx(eps_min_eq11(16), rel=1e-15)
    # half bridge buys 2×, full bending 4×, a gain of 10 another 10×
    assert min_detectable_strain(cfg, arrangement="half_bending") == pytest.approx(2 ** -25)
    assert min_detectable_strain(cfg) == pytest.approx(2 ** -26)
    assert min_detectable_strain(cfg.replace(gain=10.0)) == pytest.approx(2 ** -26 / 10)
    assert min_detectable_torque_Nm(1e-4, cfg) == pytest.approx(2 ** -26 / 1e-4)
    with pytest.raises(InputError, match="method='noise'"):
        min_detectable_strain(cfg, averaging=4)
    with pytest.raises(InputError, match="method"):
        min_detectable_strain(cfg, method="magic")


def test_johnson_noise_1k_300K():
    assert johnson_density_V_per_rtHz(1000.0, 300.0) == pytest.approx(4.07e-9, rel=1e-3)


def test_amplifier_1_over_f_matches_numerical_integral():
    en, fc, b, flo = 8e-9, 50.0, 2000.0, 0.1
    ref = en * math.sqrt(quad(lambda f: 1 + fc / f, flo, b, limit=200, epsrel=1e-12)[0])
    assert amplifier_noise_rms_V(en, fc, b, flo) == pytest.approx(ref, rel=1e-9)


def test_noise_budget_paper_and_quadrature():
    cfg = SensorConfig()
    bud = noise_budget(cfg, 5.7e-4)
    assert bud.bandwidth_Hz == 2000.0
    assert bud.total_V == pytest.approx(math.sqrt(sum(v ** 2 for v in bud.terms_V.values())))
    # ENOB 16 (ti) over FSR 5 V → 76.3 µV; it dominates; Johnson = 4.07 nV·√2000
    assert bud.dominant == "adc"
    assert math.hypot(bud.terms_V["adc"], bud.terms_V["quantization"]) == \
        pytest.approx(5.0 / 2 ** 16, rel=1e-12)
    assert bud.terms_V["johnson"] == pytest.approx(4.0704e-9 * math.sqrt(2000), rel=1e-3)
    assert bud.total_strain == pytest.approx(bud.total_V / 10.0)
    assert bud.total_Nm == pytest.approx(bud.total_strain / 5.7e-4)
    # averaging 4 samples halves every (white, dithered) term
    assert noise_budget(cfg, averaging=4).total_V == pytest.approx(bud.total_V / 2, rel=1e-12)
    assert noise_budget(cfg, bandwidth_Hz=20.0).total_V == pytest.approx(bud.total_V / 10,
                                                                            rel=1e-12)
    with pytest.raises(InputError, match="bandwidth_Hz"):
        noise_budget(cfg, bandwidth_Hz=5000.0)
    assert min_detectable_strain(cfg, method="noise", averaging=4) == \
        pytest.approx(bud.total_strain / 2, rel=1e-12)


def test_budget_dominant_term_moves_with_gain():
    cfg = SensorConfig(gain=1000.0, noise_V_per_rtHz=10e-9, rated_strain=1e-4)
    bud = noise_budget(cfg)
    assert bud.dominant == "amplifier"
    assert bud.terms_V["adc"] == pytest.approx(noise_budget(SensorConfig()).terms_V["adc"] / 1000)
    quiet = SensorConfig(gain=1000.0, rated_strain=1e-4)             # noiseless amplifier
    assert noise_budget(quiet).dominant == "johnson"


def test_adc_noise_scales_with_data_rate():
    a = SensorConfig(data_rate_Hz=4000.0, enob_data_rate_Hz=4000.0)
    b = SensorConfig(data_rate_Hz=16000.0, enob_data_rate_Hz=4000.0)
    assert b.adc_noise_rms_V == pytest.approx(2 * a.adc_noise_rms_V)


# ---------------------------------------------------------------- configuration
def test_paper_toml_is_the_default_config():
    cfg, spn = load_sensor_config(ROOT / "sensors" / "paper_sensor.toml")
    assert cfg == SensorConfig()
    from bridge.chain import PAPER_STRAIN_PER_NM
    assert spn == pytest.approx(PAPER_STRAIN_PER_NM, rel=1e-15)


@pytest.mark.parametrize("section,key,value,match", [
    ("bridge", "gauge_resistance_ohm", -1000.0, "bridge.gauge_resistance_ohm"),
    ("bridge", "gauge_resistance_ohm", 0.0, "bridge.gauge_resistance_ohm"),
    ("bridge", "excitation_V", 0.0, "bridge.excitation_V"),
    ("bridge", "rated_strain", 0.05, "bridge.rated_strain"),
    ("bridge", "arrangement", "eighth", "bridge.arrangement"),
    ("bridge", "lead_resistance_ohm", -1.0, "bridge.lead_resistance_ohm"),
    ("amplifier", "gain", 0.0, "amplifier.gain"),
    ("amplifier", "gain", -5.0, "amplifier.gain"),
    ("amplifier", "gain", 1000.0, "saturates"),
    ("adc", "v_ref_V", -2.5, "adc.v_ref_V"),
    ("adc", "bits", 0, "adc.bits"),
    ("adc", "bits", 16.5, "adc.bits"),
    ("adc", "enob", 25.0, "adc.enob"),
    ("adc", "enob_definition", "snr", "adc.enob_definition"),
    ("adc", "range_factor", 3, "adc.range_factor"),
    ("adc", "data_rate_Hz", "fast", "adc.data_rate_Hz"),
    ("adc", "colour", 1, "adc.colour: unknown field"),
    ("torque", "strain_per_Nm", -1.0, "torque.strain_per_Nm"),
])
def test_bad_config_names_the_field(section, key, value, match):
    with pytest.raises(InputError, match=match) as info:
        sensor_config_from_dict({section: {key: value}}, source="s.toml")
    assert str(info.value).startswith("s.toml: ")


def test_bad_toml_names_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[adc\nbits = 24\n")
    with pytest.raises(InputError, match="bad.toml"):
        load_sensor_config(p)
    with pytest.raises(InputError, match="adcc: unknown field \\(did you mean 'adc'\\?\\)"):
        sensor_config_from_dict({"adcc": {}})
    with pytest.raises(InputError, match="unknown sensor parameter"):
        SensorConfig().replace(gian=2.0)


def test_pattern_table():
    assert pattern("full_poisson", 0.3).tolist() == [1.0, -1.0, 0.3, -0.3]
    assert pattern("full_poisson_iii", 0.3).tolist() == [1.0, -0.3, 1.0, -0.3]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        output_ratio(gauge_strains(1e-3, "full_bending"), "full_bending")   # no warning in range
