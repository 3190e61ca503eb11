"""`torquebench compare`: a 10× less sensitive flexure gives 10× the torque noise and a larger
predicted and simulated localization error, in the JSON and the plot."""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_compare_two_strains_end_to_end(tmp_path, cli_inprocess, monkeypatch):
    png = tmp_path / "cmp.png"
    monkeypatch.setenv("TORQUEBENCH_CACHE", str(tmp_path / "cache"))
    r = cli_inprocess("compare", "scenes/end_to_end.toml", "--vary", "flexure=5e-5,5e-4", "--png", png,
                      "--json", cwd=ROOT)
    assert r.returncode == 0, r.stderr
    lo, hi = json.loads(r.stdout)["rows"]
    assert hi["torque_noise_std_Nm"] < 0.2 * lo["torque_noise_std_Nm"]
    for k in ("predicted_position_rms_m", "simulated_position_rms_m"):
        assert hi[k] < lo[k]
    for row in (lo, hi):
        assert abs(row["simulated_position_rms_m"] / row["predicted_position_rms_m"] - 1) < 0.3
    assert png.read_bytes()[:4] == b"\x89PNG"
