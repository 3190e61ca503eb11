"""Pictures of a URDF robot (pyvista, off-screen): each link's surface coloured by the predicted
localization error (estimator.spatial.predict), and an estimated contact with its force arrow
beside the true one."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from estimator.spatial.tree import body_poses


def _plotter():
    from userio.offscreen import prefer_headless

    prefer_headless()                      # no reachable X server: EGL (no X warning on stderr)
    import pyvista as pv

    pv.OFF_SCREEN = True
    return pv.Plotter(off_screen=True, window_size=(900, 900))


def _poly(vertices, faces):
    import pyvista as pv

    return pv.PolyData(vertices, np.c_[np.full(len(faces), 3), faces].ravel())


def _world(model, q):
    R, p, _, _ = body_poses(model.tree, np.asarray(q, float)[None])
    return R[0], p[0]


def _save(pl, path):
    from userio.files import atomic_path

    with atomic_path(Path(path)) as tmp:
        pl.screenshot(str(tmp) if str(tmp).endswith(".png") else str(tmp), return_img=False)
    pl.close()


def error_picture(model, q, maps, path, title="predicted contact-localization error") -> Path:
    """The robot at q with each solid coloured by its RMS position error (mm); grey: refused."""
    R, p = _world(model, q)
    pl = _plotter()
    for m in maps:
        mesh = _poly(p[m.body] + m.vertices @ R[m.body].T, m.faces)
        mesh["error_mm"] = m.error_m * 1e3
        pl.add_mesh(mesh, scalars="error_mm", nan_color="lightgrey", cmap="viridis",
                    scalar_bar_args={"title": "RMS error [mm]"}, clim=_clim(maps))
    pl.add_text(title, font_size=11)
    pl.view_isometric()
    _save(pl, path)
    return Path(path)


def _clim(maps):
    e = np.concatenate([m.error_m for m in maps]) * 1e3
    e = e[np.isfinite(e)]
    return (float(e.min()), float(np.percentile(e, 98))) if e.size else (0.0, 1.0)


def contact_picture(model, q, maps, est_point, est_force, true_point=None, true_force=None,
                    path="contact.png", arrow_m_per_N=0.03) -> Path:
    """The robot at q (surfaces grey), the estimated contact (red sphere) with its force arrow
    (pointing where the force pushes, ending at the contact) and the true one (green)."""
    import pyvista as pv

    R, p = _world(model, q)
    pl = _plotter()
    for m in maps:
        pl.add_mesh(_poly(p[m.body] + m.vertices @ R[m.body].T, m.faces), color="lightgrey", opacity=0.6)
    for point, force, color, label in ((est_point, est_force, "red", "estimated"),
                                       (true_point, true_force, "green", "true")):
        if point is None or not np.all(np.isfinite(point)):
            continue
        point, force = np.asarray(point, float), np.asarray(force, float)
        pl.add_mesh(pv.Sphere(radius=0.008, center=point), color=color, label=label)
        vec = force * arrow_m_per_N
        pl.add_mesh(pv.Arrow(start=point - vec, direction=vec, scale="auto", tip_length=0.25,
                             tip_radius=0.08, shaft_radius=0.03), color=color)
    pl.add_legend()
    pl.view_isometric()
    _save(pl, path)
    return Path(path)
