"""Cache keys hash the source a stage depends on, derived from the import graph
(torquebench.stages.codedeps): an edit in flexure/ re-runs the FEM (and what depends on its
result), never the robot simulation; an edit in estimator/ re-runs the simulation and the
estimates, never the FEM or the calibration fit; an edit of a file a stage imports (at any depth,
at module or function level) changes its key and not the key of a stage that does not."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from torquebench import pipeline as P
from torquebench.scenes import load_scene
from torquebench.stages import codedeps, registry

ROOT = Path(__file__).resolve().parents[1]
E2E = ROOT / "scenes" / "end_to_end.toml"
CHAIN = {"flexure_fem", "sensor_chain", "calibration_session", "calibration_fit"}


@pytest.fixture
def source_copy(tmp_path, monkeypatch):
    """A temporary copy of the packages the keys hash, made the hashed source root."""
    for pkg in ("userio", "bridge", "flexure", "calibration", "estimator", "torquebench"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__", "data"))
    monkeypatch.setattr(codedeps, "SOURCE_ROOT", tmp_path)
    codedeps.clear()
    yield tmp_path
    codedeps.clear()


def _keys(scene):
    codedeps.clear()
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
    """bridge/config.py (the sensor file) is read by the FEM's figures and by the chain every
    other stage reads; bridge/chain.py by every stage but the FEM (flexure uses the bridge's
    config, budget and wheatstone modules, not the chain)."""
    scene = load_scene(E2E)
    k0 = _keys(scene)
    _touch(source_copy / "bridge" / "chain.py")
    k1 = _keys(scene)
    assert _changed(k0, k1) == set(k0) - {"flexure_fem"}
    _touch(source_copy / "bridge" / "config.py")
    assert _changed(k1, _keys(scene)) == set(k0)  # every stage calls bridge or reads its results


def test_source_hashes_are_read_once_per_process(source_copy):
    st = registry.by_gives()["estimates"]
    codedeps.stage_code(st)
    before = codedeps.file_hash.cache_info().hits
    for _ in range(5):
        codedeps.stage_code(st)
    assert codedeps.file_hash.cache_info().hits >= before + 5


def _stage(name):
    return next(s for s in registry.stages() if s.name == name)


@pytest.mark.slow
def test_editing_a_file_changes_the_key_of_exactly_the_stages_whose_import_closure_holds_it(source_copy):
    """For several files: the stages whose derived code holds the file change key, and only those
    and the stages downstream of them (their upstream key changed); a stage whose closure lacks
    the file keeps its key."""
    scene = load_scene(E2E)
    plan0 = {s.stage.name: s for s in P.plan(scene, None, None) if s.action == "run"}
    down = {}                                     # stage -> the planned stages it reads, transitively
    producer = {s.stage.gives: n for n, s in plan0.items()}

    def upstream(name):
        if name not in down:
            st = plan0[name].stage
            direct = {producer[a] for a in st.inputs_declared if a in producer and st.uses(scene, a)}
            down[name] = direct.union(*(upstream(d) for d in direct)) if direct else set()
        return down[name]

    k1 = _keys(scene)
    for rel in ("flexure/convergence.py", "calibration/fit.py", "torquebench/stages/scoring.py",
                "torquebench/stages/simulation.py"):
        k0 = k1
        holding = {n for n in plan0 if rel in codedeps.stage_files(_stage(n))}
        _touch(source_copy / rel)
        k1 = _keys(scene)
        expected = {n for n in plan0 if n in holding or upstream(n) & holding}
        assert _changed(k0, k1) == expected, rel
        assert holding and set(plan0) - expected, rel    # some stage holds it, some does not


def test_the_derived_code_follows_imports_inside_functions_and_package_inits():
    """run_flexure_fem imports flexure.convergence inside the function: its key holds that file,
    the flexure package __init__ and what convergence imports; the sensor chain's does not hold
    the FEM's files; the simulation's holds the simulator and not the calibration fit."""
    fem, chain, sim = (set(codedeps.stage_files(_stage(n)))
                       for n in ("flexure_fem", "sensor_chain", "simulation"))
    assert {"flexure/convergence.py", "flexure/__init__.py", "torquebench/stages/flexure.py"} <= fem
    assert not any(f.startswith("flexure/") for f in chain)
    assert "bridge/chain.py" in chain
    assert "estimator/sim/__init__.py" in sim and "calibration/fit.py" not in sim
    import ast
    src = (ROOT / "flexure/convergence.py").read_text()
    imported = {n.module for n in ast.walk(ast.parse(src)) if isinstance(n, ast.ImportFrom) and n.module
                and n.module.split(".")[0] == "flexure"}
    for mod in imported:                         # every flexure module convergence imports
        f = mod.replace(".", "/")
        assert f + ".py" in fem or f + "/__init__.py" in fem, mod


def test_the_files_a_design_names_are_part_of_its_key(tmp_path):
    """Editing the STL (or STEP) part or the bridge sensor a design names re-runs the FEM."""
    design = tmp_path / "part.toml"
    design.write_text('[geometry]\nkind = "stl"\nfile = "part.stl"\n[bridge]\nsensor = "s.toml"\n')
    (tmp_path / "part.stl").write_text("solid a\nendsolid a\n")
    (tmp_path / "s.toml").write_text("[bridge]\n")
    before = P.design_hash(design)
    (tmp_path / "part.stl").write_text("solid b\nendsolid b\n")
    after_part = P.design_hash(design)
    (tmp_path / "s.toml").write_text("[bridge]\nexcitation_V = 5.0\n")
    after_sensor = P.design_hash(design)
    assert before["design"] == after_part["design"] == after_sensor["design"]
    assert before != after_part != after_sensor


def test_scene_values_key_exactly_not_by_their_printed_form():
    """repr() of an array keeps 8 digits and elides long arrays; the key must not."""
    from dataclasses import replace

    from estimator.robot import paper_leg

    robot = paper_leg()
    nudged = replace(robot, masses_kg=robot.masses_kg * (1 + 1e-12))
    assert repr(robot) == repr(nudged)                    # the printed form cannot tell them apart
    assert P.canon(robot) != P.canon(nudged)
    long_a, long_b = np.zeros(5000), np.zeros(5000)
    long_b[2500] = 1.0
    assert repr(long_a) == repr(long_b)
    assert P.canon(long_a) != P.canon(long_b)
    assert P.canon(robot) == P.canon(replace(robot))   # equal values, equal keys


def test_the_fast_import_reader_finds_every_import_a_full_parse_finds():
    """codedeps reads only the import statements' text; on every project file it must find each
    import statement the full ``ast`` walk (module and function level) finds."""
    import ast

    for pkg in ("userio", "bridge", "flexure", "calibration", "estimator", "torquebench"):
        for f in (ROOT / pkg).rglob("*.py"):
            text = f.read_text()
            full = {ast.dump(n) for n in codedeps._import_statements(ast.parse(text).body)}
            fast = {ast.dump(n) for n in codedeps._import_nodes(text, str(f))}
            assert full <= fast, (f, full - fast)
    tricky = "import os; import sys\ndef f():\n    from bridge import \\\n        chain\n"
    assert {type(n).__name__ for n in codedeps._import_nodes(tricky, "x.py")} == {"Import", "ImportFrom"}
    assert len(codedeps._import_nodes(tricky, "x.py")) == 3
