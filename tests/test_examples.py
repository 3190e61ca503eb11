"""The example logs shipped in examples/ are what they claim to be.

examples/sim/: re-simulating the scene gives the shipped file again (same seed, same integrator),
and `estimate` finds the applied contact in it. examples/leg_poke/: the independent log is present
(a fresh clone needs nothing beside it). Nothing here refers outside the repository.
"""

import io
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import shared_result

ROOT = Path(__file__).resolve().parents[1]
SIM = ROOT / "examples" / "sim"
SCENES = ("paper_floating_link1", "paper_fixed_link2")
# this file names the string it looks for; README.md's examples are checked by test_readme.py
OWN_CHECKS = {"tests/test_examples.py"}


def _tb(*argv, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "torquebench", *map(str, argv)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def _declared_sigma(log: Path, columns: list[str]) -> dict[str, float]:
    """Column → the 1σ noise the log's declaration (LOG.noise.toml) gives it."""
    from estimator.log_declarations import read_noise_declaration

    taus = [c for c in columns if c.startswith("tau")]
    noise = read_noise_declaration(log, len(taus))
    out = dict(zip(taus, np.broadcast_to(noise.torque_sigma_Nm, (len(taus),)).tolist()))
    out.update((c, s) for c, s in zip(("Fx", "Fz", "My"), noise.ft_sigma.tolist()) if c in columns)
    return out


def _simulate(scene: str):
    """`torquebench simulate` of a shipped scene → (exit code, stderr, {file name: bytes})."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        proc = _tb("simulate", ROOT / "scenes" / f"{scene}.toml", "--out", Path(d) / "log.csv")
        return proc.returncode, proc.stderr, {f.name: f.read_bytes() for f in Path(d).iterdir()}


@pytest.fixture(scope="module", params=SCENES)
def simulated(request, tmp_path_factory):
    """The scene re-simulated by the CLI once per run (shared by the workers and by the two tests
    below), its files written to a fresh directory: (scene, exit code, stderr, directory)."""
    scene = request.param
    code, err, files = shared_result("simulate-" + scene, lambda: _simulate(scene),
                                     str(ROOT / "scenes" / f"{scene}.toml"))
    d = tmp_path_factory.mktemp(scene)
    for name, data in files.items():
        (d / name).write_bytes(data)
    return scene, code, err, d


def test_shipped_sim_log_is_what_the_simulator_makes(simulated):
    scene, code, err, tmp_path = simulated
    assert code == 0, err
    for made, shipped in ((tmp_path / "log.csv", SIM / f"{scene}.csv"),
                          (tmp_path / "log.truth.csv", SIM / f"{scene}.truth.csv")):
        a, b = pd.read_csv(made), pd.read_csv(shipped)
        assert list(a.columns) == list(b.columns) and a.shape == b.shape
        # same seed and integrator. On one machine the files are equal to the printed digits; on
        # another CPU the LU round-off inside the adaptive BDF can change an accepted step: the
        # integrated states then agree to the integrator's tolerance (≤ 10 × (rtol·|column| + atol)
        # accumulated; measured up to 4.6×), and the sensor channels, which the controller's gains and the
        # dynamics amplify, to far below the noise the log declares (< 1 % of its σ; measured 0.4 %)
        integ = tomllib.loads((ROOT / "scenes" / f"{scene}.toml").read_text())["integrator"]
        scale = np.nanmax(np.abs(b.to_numpy()), axis=0)
        bound = 10.0 * (integ["rtol"] * scale + integ["atol"]) + 1e-12
        for col, sigma in _declared_sigma(SIM / f"{scene}.csv", list(b.columns)).items():
            bound[list(b.columns).index(col)] = 0.01 * sigma
        diff = np.nan_to_num(np.abs(a.to_numpy() - b.to_numpy()))
        np.testing.assert_array_less(diff, np.broadcast_to(bound, diff.shape))
        assert np.array_equal(np.isnan(a.to_numpy()), np.isnan(b.to_numpy()))


def test_shipped_noise_declaration_is_what_the_simulator_writes(simulated):
    """`simulate` declares the sensor noise it drew (LOG.noise.toml); the shipped one matches."""
    scene, code, err, tmp_path = simulated
    assert code == 0, err
    assert (tmp_path / "log.noise.toml").read_text() == (SIM / f"{scene}.noise.toml").read_text()


def _estimate(log: Path):
    """`torquebench estimate LOG --out EST --json` → (exit code, stderr, stdout, EST's text)."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / f"{log.stem}.est.csv"
        proc = _tb("estimate", log, "--out", out, "--json")
        return proc.returncode, proc.stderr, proc.stdout, out.read_text() if out.is_file() else ""


@pytest.fixture(scope="module", params=SCENES)
def estimated(request):
    """The shipped log of a scene estimated once per run by the CLI, with its noise declaration
    (shared by the workers and by the two tests below): (scene, exit code, stderr, stdout, CSV)."""
    log = SIM / f"{request.param}.csv"
    return (request.param, *shared_result("estimate-" + request.param, lambda: _estimate(log),
                                          str(log), str(SIM / f"{request.param}.noise.toml")))


def test_declared_noise_keeps_contact_free_samples_quiet(estimated, tmp_path):
    """With the log's noise declaration the chi-square detector at 1/h flags under 1 % of the
    contact-free samples (the fixed-base log keeps 6: its unlogged stiff mount settles in the
    first 6 ms); the same log estimated as if its sensors were the default paper leg's
    (τ σ 0.005 N·m against the 0.0133 the bridge chain drew) flags more than 3 %."""
    scene = estimated[0]
    truth = pd.read_csv(SIM / f"{scene}.truth.csv")
    t_on, t_off = truth.t[truth.link > 0].iloc[[0, -1]]
    free = ((truth.t < t_on) | (truth.t > t_off + 0.1)).to_numpy()

    def flagged(code, err, out, csv):
        assert code == 0, err
        return pd.read_csv(io.StringIO(csv)).contact.to_numpy(bool)[free].mean(), json.loads(out)

    declared, summary = flagged(*estimated[1:])
    assert "log declaration" in summary["residual_noise_source"]
    bare = tmp_path / "bare.csv"                       # the same log without its noise declaration
    bare.write_bytes((SIM / f"{scene}.csv").read_bytes())
    default, summary = flagged(*_estimate(bare))
    assert "default noise" in summary["residual_noise_source"]
    print(f"{scene}: contact-free flagged {declared:.2%} declared, {default:.2%} default")
    assert declared < 0.01 < 0.03 < default, (declared, default)


def test_estimate_finds_the_true_contact_in_the_shipped_log(estimated):
    scene, code, err, out, _ = estimated
    truth = pd.read_csv(SIM / f"{scene}.truth.csv")
    touching = truth[truth.link > 0]
    link, alpha = int(touching.link.iloc[0]), float(touching.alpha.iloc[0])
    assert code == 0, err
    longest = max(json.loads(out)["intervals"], key=lambda iv: iv["samples"])
    assert longest["link"] == link
    assert abs(longest["alpha"] - alpha) < 0.05
    assert abs(longest["t_start_s"] - touching.t.iloc[0]) < 0.02


def test_leg_poke_sample_is_in_the_repository():
    for name in ("leg_poke.csv", "leg_poke.truth.csv", "README.md"):
        assert (ROOT / "examples" / "leg_poke" / name).is_file(), name
    assert "independent" in (ROOT / "examples" / "leg_poke" / "README.md").read_text(encoding="utf-8")


OUTSIDE_NAMES = ("../shared", "DESIGN.md", "paper.md")   # files a fresh clone does not hold


def test_nothing_in_the_repository_points_outside_it():
    """No tracked text file refers to ../shared or cites a file the repository does not hold
    (DESIGN.md, paper.md: a fresh clone has nothing beside it)."""
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    offenders = []
    for name in files:
        path = ROOT / name
        if path.suffix not in {".py", ".md", ".toml", ".sh", ".txt", ".cfg"} or not path.is_file():
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        if name not in OWN_CHECKS and any(s in text for s in OUTSIDE_NAMES):
            offenders.append(name)
    assert offenders == []
