"""Off-screen rendering (pyvista/VTK) that never asks for an X server it cannot reach.

VTK's default render window on Linux is X11 (vtkXOpenGLRenderWindow); without a reachable X
display it prints ``bad X server connection. DISPLAY=...`` on stderr (and then falls back to EGL
or OSMesa when the wheel has them). ``prefer_headless()``, called before the first render window is
made, picks EGL (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``, honoured by VTK ≥ 9.4 wheels)
when DISPLAY is unset or names a local display whose socket (/tmp/.X11-unix/X<N>) does not exist.
A window class the user set is kept.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

EGL_WINDOW = "vtkEGLRenderWindow"


def x_display_reachable(display: str | None = None) -> bool:
    """Whether DISPLAY (or ``display``) names an X server: unset → False; a local display ``:N``
    (or ``unix:N``) → its socket exists; a remote one (host:N) → assumed reachable."""
    display = os.environ.get("DISPLAY") if display is None else display
    if not display:
        return False
    m = re.fullmatch(r"(?:unix)?:(\d+)(?:\.\d+)?", display.strip())
    if m is None:
        return True
    return Path(f"/tmp/.X11-unix/X{m.group(1)}").exists()


def prefer_headless() -> None:
    """Choose EGL for VTK's render windows unless an X display is reachable (module docstring)."""
    if not x_display_reachable():
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", EGL_WINDOW)
