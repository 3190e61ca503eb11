"""`torquebench bridge`: JSON contract, defaults = the paper's sensor, bad input → exit 2."""

import json

import pytest

from torquebench.cli import main


def _run(capsys, *argv):
    code = main(["bridge", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_bridge_json_paper_defaults(capsys):
    code, out, err = _run(capsys, "--json")
    assert code == 0
    data = json.loads(out)
    assert data["eps_min_ideal"] == pytest.approx(5.96e-8, rel=1e-3)
    assert data["eps_min_enob"] == pytest.approx(1.53e-5, rel=3e-3)
    assert data["dominant_noise"] == "adc"
    assert data["noise_rms_V"] == pytest.approx(5.0 / 2 ** 16, rel=1e-4)
    assert data["min_detectable_torque_Nm"] == pytest.approx(data["noise_rms_Nm"])
    assert data["sensitivity_V_per_Nm"] == pytest.approx(5.718e-3, rel=1e-3)


def test_bridge_strain_per_Nm_and_averaging(capsys):
    code, out, _ = _run(capsys, "--json", "--strain-per-Nm", "1e-4", "--averaging", "16")
    data = json.loads(out)
    assert code == 0 and data["strain_per_Nm"] == 1e-4
    assert data["min_detectable_torque_Nm"] == pytest.approx(5.0 / 2 ** 16 / 4 / 10.0 / 1e-4,
                                                             rel=1e-4)


def test_bridge_text_output(capsys):
    code, out, _ = _run(capsys)
    assert code == 0 and "dominant noise: adc" in out and "5.96e-08" in out


def test_bridge_without_strain_per_Nm_omits_torque(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text('[bridge]\narrangement = "quarter"\n')
    code, out, _ = _run(capsys, str(p), "--json")
    data = json.loads(out)
    assert code == 0 and "min_detectable_torque_Nm" not in data
    assert data["eps_min_ideal_bridge"] == pytest.approx(2.0 ** -24)


@pytest.mark.parametrize("text,needle", [
    ("[adc]\nenob = 30.0\n", "adc.enob"),
    ("[bridge]\ngauge_resistance_ohm = -1.0\n", "bridge.gauge_resistance_ohm"),
    ("[amplifier]\ngain = 1000.0\n", "saturates"),
    ("[adc\n", "invalid TOML"),
])
def test_bridge_bad_config_exit_2_one_line(tmp_path, capsys, text, needle):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    code, out, err = _run(capsys, str(p), "--json")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err and "bad.toml" in err


def test_bridge_missing_file_and_bad_option(tmp_path, capsys):
    code, out, err = _run(capsys, str(tmp_path / "nope.toml"))
    assert code == 2 and out == "" and "nope.toml" in err
    code, out, err = _run(capsys, "--strain-per-Nm", "-1")
    assert code == 2 and "--strain-per-Nm" in err
    code, out, err = _run(capsys, "--bandwidth-Hz", "1e6")
    assert code == 2 and "bandwidth_Hz" in err
