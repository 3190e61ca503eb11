"""Closed-form spoke-flexure model: N Euler–Bernoulli spokes clamped in a rigid hub and rim.

A reference for the FEM (tests, reports) and a first guess for a designer. Spoke k runs from the
hub radius a to the rim radius b (L = b − a), width w in the disc plane, thickness t; the hub
turns by θ. The spoke's hub end moves θa sideways and turns by θ, its rim end is clamped:

    V = EI/L³ (12 θa + 6L θ),  M_a = EI/L³ (6L θa + 4L² θ),  T = N (V a + M_a)
    ⇒ k = T/θ = N EI (12a² + 12aL + 4L²)/L³,   V/T = (12a + 6L) / (N (12a² + 12aL + 4L²))

with I = t w³/12. On the spoke's centre line the bending strain vanishes and a ±45° gauge reads
half the shear strain, γ/2 = τ/(2G), τ = 1.5 V/(w t) (parabolic shear); averaged over a square
g × g grid turned 45° (⟨y²⟩ = g²/12 across the width) that is × (1 − g²/(3w²)).
The model is kinematically stiffer than the solid (plane sections, rigid clamps: k is an upper
bound) and takes the shear uniform through t (Saint-Venant adds ≈ 3 % at the surface for t/w = ½).
"""

from __future__ import annotations


def guided_spokes(hub_radius_m: float, rim_radius_m: float, width_m: float, thickness_m: float,
                  spokes: int, material, gauge_size_m: float = 0.0) -> tuple[float, float]:
    """(torsional stiffness k in N·m/rad, ±45° gauge strain per N·m) of the model above."""
    a, L = hub_radius_m, rim_radius_m - hub_radius_m
    w, t = width_m, thickness_m
    poly = 12 * a * a + 12 * a * L + 4 * L * L
    k = spokes * material.E_Pa * (t * w ** 3 / 12) * poly / L ** 3
    shear_per_Nm = (12 * a + 6 * L) / (spokes * poly)
    eps = 1.5 * shear_per_Nm / (w * t) / (2 * material.shear_modulus_Pa) * (1 - gauge_size_m ** 2 / (3 * w ** 2))
    return k, eps
