"""Cache keys hash the source of the domain packages a stage calls: an edit in flexure/ re-runs
the FEM (and what depends on its result), never the robot simulation; an edit in estimator/
re-runs the simulation and the estimates, never the FEM or the calibration fit."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from torquebench import pipeline as P
from torquebench.scenes import load_scene

ROOT = Path(__file__).resolve().parents[1]
E2E = ROOT / "scenes" / "end_to_end.toml"
CHAIN = {"flexure_fem", "sensor_chain", "calibration_session", "calibration_fit"}


@pytest.fixture
def source_copy(tmp_path, monkeypatch):
    """A temporary copy of the packages the keys hash, made the hashed source root."""
    for pkg in ("bridge", "flexure", "calibration", "estimator"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__", "data"))
    (tmp_path / "torquebench" / "reports").mkdir(parents=True)
    shutil.copy(ROOT / "torquebench/reports/reproduction.py", tmp_path / "torquebench/reports")
    monkeypatch.setattr(P, "SOURCE_ROOT", tmp_path)
    P.source_hash.cache_clear()
    yield tmp_path
    P.source_hash.cache_clear()


def _keys(scene):
    P.source_hash.cache_clear()
    return {s.stage.name: s.key for s in P.plan(scene, None, None) if s.action == "run"}


def _touch(path: Path):
    path.write_text(path.read_text() + "\n# touched\n")


def _changed(before, after):
    assert before.keys() == after.keys()
    return {k for k in before if before[k] != after[k]}


def test_touching_a_package_changes_the_keys_of_the_stages_that_use_it_only(source_copy):
    scene = load_scene(E2E)
    k0 = _keys(scene)
    assert CHAIN | {"simulation", "raw_counts", "estimates"} <= set(k0)

    _touch(source_copy / "estimator" / "observer.py")
    k1 = _keys(scene)
    changed = _changed(k0, k1)
    assert {"simulation", "raw_counts", "estimates", "localization_error", "predicted_error"} <= changed
    assert not changed & CHAIN                   # no re-mesh, no refit after an estimator edit

    _touch(source_copy / "flexure" / "__init__.py")
    k2 = _keys(scene)
    changed = _changed(k1, k2)
    assert "flexure_fem" in changed
    assert "simulation" not in changed           # the robot simulation does not call flexure

    _touch(source_copy / "calibration" / "fit.py")
    changed = _changed(k2, _keys(scene))
    assert {"calibration_fit", "calibrated_torques"} <= changed
    assert not changed & {"flexure_fem", "sensor_chain", "simulation", "raw_counts"}


def test_bridge_is_imported_by_every_domain_package_so_its_edit_reaches_them(source_copy):
    scene = load_scene(E2E)
    k0 = _keys(scene)
    _touch(source_copy / "bridge" / "chain.py")
    changed = _changed(k0, _keys(scene))
    assert changed == set(k0)                    # every stage calls bridge or reads its results


def test_source_hash_is_computed_once_per_process(source_copy):
    P.source_hash("estimator")
    before = P.source_hash.cache_info().hits
    for _ in range(5):
        P.stage_code("estimates")
    assert P.source_hash.cache_info().hits >= before + 5


def test_package_import_table_covers_the_imports_in_the_source():
    """PACKAGE_IMPORTS (which domain package imports which) must hold every import the source
    really makes, or an edit would reach a stage without changing its key."""
    import re

    for pkg in P.PACKAGE_IMPORTS:
        found = set()
        for f in (ROOT / pkg).rglob("*.py"):
            found |= set(re.findall(r"^\s*(?:from|import)\s+(bridge|flexure|calibration|estimator)\b",
                                    f.read_text(), re.M))
        assert found - {pkg} <= set(P.PACKAGE_IMPORTS[pkg]), (pkg, found)
    assert set(P.STAGE_CODE) | {"report"} == {s.name for s in P.STAGES}


def test_the_files_a_design_names_are_part_of_its_key(tmp_path):
    """Editing the STL (or STEP) part or the bridge sensor a design names re-runs the FEM."""
    design = tmp_path / "part.toml"
    design.write_text('[geometry]\nkind = "stl"\nfile = "part.stl"\n[bridge]\nsensor = "s.toml"\n')
    (tmp_path / "part.stl").write_text("solid a\nendsolid a\n")
    (tmp_path / "s.toml").write_text("[bridge]\n")
    before = P._design_hash(design)
    (tmp_path / "part.stl").write_text("solid b\nendsolid b\n")
    after_part = P._design_hash(design)
    (tmp_path / "s.toml").write_text("[bridge]\nexcitation_V = 5.0\n")
    after_sensor = P._design_hash(design)
    assert before["design"] == after_part["design"] == after_sensor["design"]
    assert before != after_part != after_sensor


def test_scene_values_key_exactly_not_by_their_printed_form():
    """repr() of an array keeps 8 digits and elides long arrays; the key must not."""
    from dataclasses import replace

    from estimator.robot import paper_leg

    robot = paper_leg()
    nudged = replace(robot, masses_kg=robot.masses_kg * (1 + 1e-12))
    assert repr(robot) == repr(nudged)                    # the printed form cannot tell them apart
    assert P._canon(robot) != P._canon(nudged)
    long_a, long_b = np.zeros(5000), np.zeros(5000)
    long_b[2500] = 1.0
    assert repr(long_a) == repr(long_b)
    assert P._canon(long_a) != P._canon(long_b)
    assert P._canon(robot) == P._canon(replace(robot))   # equal values, equal keys
