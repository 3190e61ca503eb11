"""The converter's width in one place: bridge.config.SensorConfig.bits (or a sensor file's [adc]
bits). The wire frame's sample word (calibration.frames, and the firmware's tb_frame.h, which keeps
its own constant) equals that default; every rail check in Python takes the sensor's width."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from bridge.config import SensorConfig
from userio.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
HEADER = ROOT / "calibration" / "firmware" / "torquebench_adc" / "tb_frame.h"
PACKAGES = ("userio", "bridge", "flexure", "calibration", "estimator", "torquebench")


def test_firmware_frame_word_is_the_python_default_width():
    from calibration import frames

    m = re.search(r"#define\s+TB_FRAME_LEN\(n\)\s+\(\s*7\s*\+\s*(\d+)\s*\*\s*\(n\)\s*\)", HEADER.read_text())
    assert m, "TB_FRAME_LEN not found in tb_frame.h"
    assert int(m.group(1)) == frames.SAMPLE_BYTES
    assert frames.SAMPLE_BITS == SensorConfig.bits == SensorConfig().bits
    assert all(frames.frame_length(n) == 7 + int(m.group(1)) * n for n in range(1, frames.MAX_CHANNELS + 1))
    # the word round-trips its extreme codes
    seq = np.arange(2)
    codes = np.array([[frames.SAMPLE_MIN], [frames.SAMPLE_MAX]])
    _, got = frames.FrameParser(1).feed(frames.encode_frames(seq, codes))
    np.testing.assert_array_equal(got, codes)


def test_no_python_module_writes_the_width_as_a_literal():
    pat = re.compile(r"2\s*\*\*\s*2[34]\b|1\s*<<\s*2[34]\b|code_limits\(\s*\d+\s*\)|0xFFFFFF\b")
    hits = [f"{f.relative_to(ROOT)}:{i}: {line.strip()}"
            for pkg in PACKAGES for f in sorted((ROOT / pkg).rglob("*.py"))
            for i, line in enumerate(f.read_text().splitlines(), 1)
            if pat.search(line.split("#")[0]) and "_BYTES" not in line]      # buffer sizes are not widths
    assert not hits, hits


def test_rails_follow_the_sensors_width():
    from calibration.fit import check_readings
    from calibration.model import SensorModel, adc_rails

    assert adc_rails() == (-(1 << (SensorConfig.bits - 1)), (1 << (SensorConfig.bits - 1)) - 1)
    assert adc_rails(16) == (-32768, 32767)
    base = dict(model="linear", coef_names=("slope", "offset"), coef_mean=np.array([100.0, 0.0]),
                coef_cov=np.eye(2) * 1e-6, sigma=1.0, samples=np.zeros((4, 2)), sigma_samples=np.ones(4),
                lever_arm_m=0.2, reading_unit="counts")
    assert SensorModel(**base, adc_bits=16).flags([32767.0, 100.0]).tolist() == ["saturated_adc", ""]
    assert SensorModel(**base).flags([32767.0]).tolist() == [""]
    check_readings(np.r_[np.full(6, 32767.0), np.arange(4.0)], "s.csv")       # fine at 24 bits
    with pytest.raises(InputError, match="ADC full scale"):
        check_readings(np.r_[np.full(6, 32767.0), np.arange(4.0)], "s.csv", adc_bits=16)


def test_a_scenes_width_is_its_sensor_files(tmp_path):
    from torquebench.pipeline import adc_bits
    from torquebench.scenes import load_scene

    sensor = tmp_path / "s.toml"
    sensor.write_text((ROOT / "sensors" / "paper_sensor.toml").read_text().replace("bits = 24", "bits = 20"))
    text = (ROOT / "scenes" / "paper_floating_link2.toml").read_text()
    (tmp_path / "a.toml").write_text(text)
    (tmp_path / "b.toml").write_text(text + f'\n[sensor]\nfile = "{sensor}"\n')
    assert adc_bits(load_scene(tmp_path / "a.toml")) == SensorConfig.bits
    assert adc_bits(load_scene(tmp_path / "b.toml")) == 20
