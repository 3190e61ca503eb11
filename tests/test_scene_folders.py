"""scenes/ holds only scenes; flexure designs live in designs/ and sensor files in sensors/, and a
path inside a file is resolved from the file that names it (so the moves keep every link)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_file_in_scenes_is_a_scene():
    from estimator.spatial.scene import is_spatial_scene
    from torquebench.scenes import load_scene

    for p in sorted((ROOT / "scenes").glob("*.toml")):
        if is_spatial_scene(p):
            continue
        assert load_scene(p).name, p


def test_designs_and_sensors_load_from_their_folders_with_their_relative_links():
    from bridge.config import load_sensor_config
    from flexure.design import load_design
    from torquebench.scenes import load_scene
    from torquebench.stages.cachekey import design_hash

    designs, sensors = sorted((ROOT / "designs").glob("*.toml")), sorted((ROOT / "sensors").glob("*.toml"))
    assert designs and sensors
    for p in sensors:
        assert load_sensor_config(p)[0].bits > 0
    for p in designs:
        d = load_design(p)
        assert d.rated_torque_Nm > 0
    key = design_hash(ROOT / "designs" / "paper_disc.toml")       # its [bridge] sensor, read from designs/
    assert key["bridge.sensor"] == design_hash.__globals__["file_hash"](ROOT / "sensors" / "paper_sensor.toml")
    scene = load_scene(ROOT / "scenes" / "end_to_end.toml")        # links resolved from scenes/
    assert scene.chain.flexure_design.resolve() == (ROOT / "designs" / "paper_disc.toml").resolve()
    assert scene.chain.sensor_file.resolve() == (ROOT / "sensors" / "paper_sensor.toml").resolve()
