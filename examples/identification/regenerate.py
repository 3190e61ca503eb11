"""Regenerate this example: a MuJoCo log (tests/mujoco_leg.py, a simulator that shares no code with
torquebench's) of a paper leg whose inertial data differ from robots/paper_leg.toml the way a CAD
model's do, running the shipped excitation trajectory, with declared sensor noise.

    python examples/identification/regenerate.py          (needs `pip install mujoco`)
"""

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from mujoco_leg import mujoco_log  # noqa: E402

from estimator.inertial import robot_toml  # noqa: E402
from estimator.noise import NoiseModel, noise_toml  # noqa: E402
from estimator.robot import paper_leg  # noqa: E402
from estimator.sim.output import log_csv, timing_toml  # noqa: E402
from torquebench.scenes import load_scene, scene_path  # noqa: E402
from userio.files import write_files_atomic  # noqa: E402

nominal = paper_leg()
cad = replace(nominal, name="cad_leg", masses_kg=nominal.masses_kg * [1.045, 0.96],
              com_m=nominal.com_m + [0.0025, -0.003], com_perp_m=np.array([0.002, -0.0028]),
              inertias_kgm2=nominal.inertias_kgm2 * [0.91, 1.08],
              base_mass_kg=nominal.base_mass_kg * 1.035, base_inertia_kgm2=nominal.base_inertia_kgm2 * 1.18)
ctrl = load_scene(scene_path("identification_excitation")).sim.controller
A, f, ph = ctrl.harmonics()
log, _ = mujoco_log(cad, ctrl.q0_rad, 6.0, amplitude=A, frequency_Hz=f, phase=ph, seed=2026,
                    tau_sigma=0.005, ft_sigma=(0.1, 0.1, 0.01))
noise = NoiseModel([0.005], [0.1, 0.1, 0.01], source="MuJoCo example: drawn with these σ")
out = HERE / "excitation.csv"
write_files_atomic([
    (out, log_csv(log)),
    (HERE / "excitation.timing.toml", timing_toml(log).replace("torquebench's simulator", "tests/mujoco_leg.py (MuJoCo)")),
    (HERE / "excitation.noise.toml", noise_toml(noise, "tests/mujoco_leg.py (MuJoCo)")),
    (HERE / "cad_leg.toml", robot_toml(cad, header="# The leg that made excitation.csv (the truth `identify` "
                                                  "should find); robots/paper_leg.toml is its nominal file.")),
])
print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB)")
