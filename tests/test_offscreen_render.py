"""Off-screen pictures (pyvista/VTK) print no "bad X server connection" warning when there is no
X server: DISPLAY unset or naming a local display whose socket does not exist
(userio.offscreen.prefer_headless, called before every render window)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from userio.offscreen import x_display_reachable

pytest.importorskip("pyvista")
ROOT = Path(__file__).resolve().parents[1]

SPATIAL = """
import pyvista as pv
from estimator.spatial.render import _plotter, _save
pl = _plotter()
pl.add_mesh(pv.Sphere())
_save(pl, {png!r})
"""


def _env(display):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "VTK_DEFAULT_OPENGL_WINDOW")}
    if display is not None:
        env["DISPLAY"] = display
    return env


def test_display_reachability():
    assert not x_display_reachable("")
    assert not x_display_reachable(":987")                      # no /tmp/.X11-unix/X987
    assert x_display_reachable("otherhost:0")                    # remote: VTK's to try


@pytest.mark.parametrize("display", [None, ":987"])
def test_spatial_render_prints_no_x_warning(tmp_path, display):
    png = tmp_path / "robot.png"
    proc = subprocess.run([sys.executable, "-c", SPATIAL.format(png=str(png))], cwd=ROOT, env=_env(display),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert png.stat().st_size > 1000
    assert "X server" not in proc.stderr and "DISPLAY" not in proc.stderr, proc.stderr


@pytest.mark.slow
def test_estimate_png_on_a_urdf_robot_prints_no_x_warning(tmp_path):
    """The reported case end to end: `estimate --png` on the shipped 3-D example log."""
    png = tmp_path / "contact.png"
    proc = subprocess.run([sys.executable, "-m", "torquebench", "estimate", "examples/spatial/leg_pokes.csv",
                           "--robot", "robots/quadruped_leg.toml", "--png", str(png)], cwd=ROOT,
                          env=_env(None), capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert png.exists()
    assert "X server" not in proc.stderr and "WARN" not in proc.stderr, proc.stderr
