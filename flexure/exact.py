"""Closed-form references for the FEM (used by its tests and benchmarks, never by a solve).

Torsion of a round annulus (r a … b, thickness t, rigid bore turned by a torque T about z, rim
clamped): u_θ(r) = B/r − B r/b² is exact (z-independent, the free faces traction-free), with
τ_rθ = −2μB/r² and T = 4πμtB, whatever a and b.
"""

from __future__ import annotations

import math

import numpy as np


def annulus_gauge_exact(design, thickness_m: float, torque_Nm: float = 1.0) -> np.ndarray:
    """Each gauge's exact read-out: ε_aa = −(B/r²)·2(e_r·a)(e_θ·a) along the gauge axis a, B =
    T/(4πμt), averaged over the gauge's grid square (tensor Gauss–Legendre 40 × 40: converged to
    1e-12 for this smooth integrand)."""
    B = torque_Nm / (4.0 * math.pi * design.material.shear_modulus_Pa * thickness_m)
    s, w = np.polynomial.legendre.leggauss(40)
    out = []
    for g in design.gauges:
        c, a, b, _ = g.frame()
        P = (c[None, None, :] + 0.5 * g.length_m * s[:, None, None] * a[None, None, :]
             + 0.5 * g.width_m * s[None, :, None] * b[None, None, :])
        r = np.hypot(P[..., 0], P[..., 1])
        er = np.stack([P[..., 0], P[..., 1], 0 * r], -1) / r[..., None]
        et = np.stack([-P[..., 1], P[..., 0], 0 * r], -1) / r[..., None]
        eps = -B / r**2 * 2.0 * (er @ a) * (et @ a)
        out.append(float(np.einsum("i,j,ij->", w, w, eps) / 4.0))
    return np.array(out)
