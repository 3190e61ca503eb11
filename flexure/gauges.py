"""Strain gauges on the flexure surface and their read-out.

A gauge is a grid of length L (along its axis a) and width W (along b = n × a) centred at c on a
surface with outward normal n. Its reading is the axial strain averaged over the grid area,

    ε_g = (1/LW) ∫∫ aᵀ ε(c + s a + t b) a ds dt,

evaluated with a tensor Gauss–Legendre rule (points moved a hair inside the solid); the strain
at the points comes from the one evaluator, ``flexure.post.strain_at``.
Bridge arms follow bridge.wheatstone's "full_bending" convention:
V_o/V_ex ≈ GF/4 (ε1 − ε2 + ε3 − ε4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexure.errors import InputError


@dataclass(frozen=True)
class Gauge:
    """One gauge: centre (m), unit axis, outward unit normal, grid length/width (m), bridge arm 1–4."""

    centre_m: tuple
    axis: tuple
    normal: tuple
    length_m: float
    width_m: float
    arm: int
    name: str = ""

    def frame(self):
        """(c, a, b, n) with a ⟂ n re-orthogonalised, b = n × a."""
        c = np.asarray(self.centre_m, float)
        n = np.asarray(self.normal, float)
        n = n / np.linalg.norm(n)
        a = np.asarray(self.axis, float)
        a = a - (a @ n) * n
        norm = np.linalg.norm(a)
        if norm < 1e-9:
            raise InputError(f"gauge {self.name or self.arm}: axis is parallel to the surface normal")
        a = a / norm
        return c, a, np.cross(n, a), n


def sample_points(gauge: Gauge, n_length: int = 6, n_width: int = 3, inset_m: float | None = None):
    """Gauss–Legendre points (k,3) over the grid and their weights (k,) summing to 1."""
    c, a, b, n = gauge.frame()
    s, ws = np.polynomial.legendre.leggauss(n_length)
    t, wt = np.polynomial.legendre.leggauss(n_width)
    S, T = np.meshgrid(s * gauge.length_m / 2, t * gauge.width_m / 2, indexing="ij")
    W = np.outer(ws, wt).ravel() / 4.0
    inset = 1e-4 * min(gauge.length_m, gauge.width_m) if inset_m is None else inset_m
    pts = c + S.ravel()[:, None] * a + T.ravel()[:, None] * b - inset * n
    return pts, W


def read(gauges: list[Gauge], strain_fn, n_length: int = 6, n_width: int = 3) -> np.ndarray:
    """Average axial strain of each gauge, (g,) — or (g, cases) when strain_fn returns
    (k, cases, 3, 3). ``strain_fn(points (k,3)) -> (k,3,3)`` or (k, cases, 3, 3)."""
    pts, w, axes = [], [], []
    for g in gauges:
        p, wg = sample_points(g, n_length, n_width)
        pts.append(p)
        w.append(wg)
        axes.append(np.repeat(g.frame()[1][None], len(p), axis=0))
    pts, w, axes = np.vstack(pts), np.concatenate(w), np.vstack(axes)
    eps = np.asarray(strain_fn(pts))
    if eps.ndim == 3:
        e_aa = np.einsum("ki,kij,kj->k", axes, eps, axes)
    else:
        e_aa = np.einsum("ki,kcij,kj->kc", axes, eps, axes)
    k = n_length * n_width
    e_aa = (e_aa * (w[:, None] if e_aa.ndim == 2 else w)).reshape(len(gauges), k, *e_aa.shape[1:])
    return e_aa.sum(axis=1)


def bridge_strains(gauges: list[Gauge], readings: np.ndarray) -> np.ndarray:
    """Order readings (g, ...) by arm → (..., 4) for bridge.wheatstone (one gauge per arm)."""
    arms = [g.arm for g in gauges]
    if sorted(arms) != [1, 2, 3, 4]:
        raise InputError(f"gauges: need exactly one gauge on each bridge arm 1–4, got arms {arms}")
    order = np.argsort(arms)
    return np.moveaxis(np.asarray(readings)[order], 0, -1)
