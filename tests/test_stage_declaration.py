"""A stage is ONE declaration (torquebench.stages.declaration.Stage): registering a new one is the
only edit needed for the planner, the cache key (its canonical inputs and its code, derived from
the imports of the module that declares it) and ``--explain`` to know it."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from torquebench.cache import Cache
from torquebench.cli import main
from torquebench.scenes import load_scene
from torquebench.stages import codedeps, registry
from torquebench.stages.declaration import Stage
from torquebench.stages.planner import execute, plan

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "paper_fixed_link1.toml"     # no FEM, no calibration fit: the chain only


def run_noise_squared(scene, inp, seed):
    """A toy stage: the square of the chain's torque noise, times the scene's true gain factor."""
    return inp["chain"].noise_std_Nm ** 2 * scene.chain.true_gain_factor


TOY = Stage("toy_noise_power", "noise_power", "σ_τ² of the sensor chain (a test's stage)",
            run_noise_squared, needs=("chain",), reads=("sensor.true_gain_factor",),
            params=lambda scene, seed: {"gain": scene.chain.true_gain_factor},
            aliases=("noise_squared",))


@pytest.fixture
def toy():
    registry.register(TOY)
    yield TOY
    registry.unregister(TOY.name)


def test_a_registered_stage_is_planned_keyed_run_cached_and_explained(toy, tmp_path, capsys):
    scene = load_scene(SCENE)
    steps = {s.stage.name: s for s in plan(scene, ["noise_power"], None)}
    assert steps["toy_noise_power"].action == "run" and steps["toy_noise_power"].reason == "requested output"
    assert steps["sensor_chain"].action == "run" and steps["sensor_chain"].reason == "needed by toy_noise_power"
    assert steps["simulation"].action == "skip"                     # nothing else is planned
    assert [s.stage.name for s in plan(scene, ["noise_squared"], None) if s.action == "run"] == \
        ["sensor_chain", "toy_noise_power"]                          # its alias asks for it too

    # its key: its params (the gain factor), upstream (the chain) and code (this file's imports)
    key = steps["toy_noise_power"].key
    other = {s.stage.name: s.key for s in plan(replace(scene, chain=replace(scene.chain, true_gain_factor=1.5)),
                                                ["noise_power"], None)}
    assert other["toy_noise_power"] != key and other["sensor_chain"] == steps["sensor_chain"].key
    files = codedeps.stage_files(toy)
    assert "tests/test_stage_declaration.py" in files
    assert "torquebench/stages/declaration.py" in files and "torquebench/cli.py" in files

    cache = Cache(tmp_path / "cache")
    counter = {}
    arts, _ = execute(scene, ["noise_power"], cache, counter=counter)
    assert arts["noise_power"] == pytest.approx(arts["chain"].noise_std_Nm ** 2 * scene.chain.true_gain_factor)
    assert counter == {"sensor_chain": 1, "toy_noise_power": 1}
    assert {s.stage.name: s.action for s in plan(scene, ["noise_power"], cache)}["toy_noise_power"] == "cached"

    assert main(["run", str(SCENE), "--explain", "--only", "noise_power", "--json",
                 "--cache-dir", str(tmp_path / "cache")]) == 0
    rows = {r["stage"]: r for r in json.loads(capsys.readouterr().out)["stages"]}
    assert rows["toy_noise_power"]["action"] == "cached"
    assert list(rows).index("toy_noise_power") > list(rows).index("sensor_chain")   # after its input


def test_without_the_declaration_the_output_is_unknown():
    with pytest.raises(Exception, match="unknown output 'noise_power'"):
        plan(load_scene(SCENE), ["noise_power"], None)


def test_a_second_producer_of_an_artifact_is_refused(toy):
    registry.register(Stage("toy_twin", "noise_power", "a second producer", run_noise_squared))
    try:
        with pytest.raises(ValueError, match="both produce 'noise_power'"):
            registry.stages()
    finally:
        registry.unregister("toy_twin")


def test_every_shipped_stage_is_declared_once_with_documented_scene_fields():
    stages = registry.stages()
    assert len({s.name for s in stages}) == len(stages) == len({s.gives for s in stages})
    for s in stages:
        assert s.doc and callable(s.run)
        if s.params is not Stage.__dataclass_fields__["params"].default:
            assert s.reads, f"{s.name}: params read the scene, `reads` names no field"
        for n in s.inputs_declared:                                  # every input has a producer
            assert n in registry.by_gives(), (s.name, n)
    order = [s.name for s in stages]
    for s in stages:                                                 # producers come first
        for n in s.inputs_declared:
            assert order.index(registry.by_gives()[n].name) < order.index(s.name)


def test_a_scene_report_plans_only_what_its_chosen_views_show():
    """`want = ["report"]` computes only the artifacts of the views drawn (and what those need):
    the bridge view of end_to_end needs the chain (and its FEM), never the simulation or the
    calibration fit; no view chosen, nothing but the summary."""
    scene = load_scene(ROOT / "scenes" / "end_to_end.toml", {"outputs.want": ["report"],
                                                              "outputs.reports": ["bridge"]})
    runs = {s.stage.name for s in plan(scene, None, None) if s.action == "run"}
    assert runs == {"flexure_fem", "sensor_chain", "report"}
    report = next(s for s in plan(scene, None, None) if s.stage.name == "report")
    assert "views: bridge +" in report.reason
    bare = load_scene(ROOT / "scenes" / "end_to_end.toml", {"outputs.want": ["report"]})
    assert {s.stage.name for s in plan(bare, None, None) if s.action == "run"} == {"report"}


def test_the_stage_graph_and_the_reproduction_report_are_in_no_import_cycle():
    """Not even through imports inside functions: the report reads the stage graph's results, the
    stages never import a report builder."""
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    from test_import_graph import cycles, import_graph

    top, inner = import_graph()
    both = {m: top[m] | inner[m] for m in top}
    assert "torquebench.stages.planner" in inner["torquebench.reports.reproduction"]
    for c in cycles(both):
        assert not any(m.startswith("torquebench.stages") or m in ("torquebench.reports.reproduction",
                                                                   "torquebench.pipeline") for m in c), c
    assert not any(m.startswith("torquebench.reports") for s in ("torquebench.stages.paper",
                   "torquebench.stages.planner") for m in top[s] | inner[s])


def test_a_new_wantable_stage_is_one_declaration_for_the_schema_and_the_docs(toy, tmp_path):
    """A scene's ``[outputs] want`` is checked by the input schema against the names the stage
    declarations offer (passed in by the reader: userio.schema.base.OneOf), and the generated
    docs/inputs.md lists them from the same place: the toy stage registered above (this file is its
    one declaration) is wantable by its alias and documented, without any other file naming it."""
    from userio.errors import InputError
    from userio.schema import docs
    from userio.schema.scene import SceneFile

    text = SCENE.read_text() + '\n[outputs]\nwant = ["noise_squared"]\n'
    (tmp_path / "s.toml").write_text(text.replace('robot = "paper_leg.toml"',
                                                  f'robot = "{ROOT / "robots" / "paper_leg.toml"}"'))
    scene = load_scene(tmp_path / "s.toml")
    assert "toy_noise_power" in {s.stage.name for s in plan(scene, None, None) if s.action == "run"}
    assert '`"noise_squared"`' in docs.render()
    schema_sources = "".join(p.read_text() for p in (ROOT / "userio" / "schema").glob("*.py"))
    assert "noise_squared" not in schema_sources and "localization_error" not in schema_sources
    registry.unregister(TOY.name)                       # without the declaration: refused, named
    try:
        with pytest.raises(InputError, match=r"outputs\.want\[1\]: must be .*'report'.*got 'noise_squared'"):
            load_scene(tmp_path / "s.toml")
        assert '`"noise_squared"`' not in docs.render()
    finally:
        registry.register(TOY)
    with pytest.raises(TypeError, match="needs context"):   # the schema holds no list of its own
        SceneFile.model_validate({"outputs": {"want": ["report"]}})
