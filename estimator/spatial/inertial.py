"""Inertial parameters of a URDF robot (``estimator.spatial.model.UrdfModel``): physical
consistency as smooth margins, a declared physical uncertainty mapped to θ, draws of it.

θ per body (pinocchio's dynamic parameters, body frame, about the body origin):
θ_b = [m, h = m c, I_o (Ixx, Ixy, Iyy, Ixz, Iyz, Izz)],  I_o = I_c + m S(c),  S(c) = |c|² 1 − c cᵀ.

Consistency (Wensing, Kim & Slotine 2017, "Linear matrix inequalities for physically consistent
inertial parameter identification"): θ_b is the moment of a nonnegative mass density iff the
pseudo-inertia J = [[Σ_o, h], [hᵀ, m]] ⪰ 0, Σ_o = ½ tr(I_o) 1 − I_o = ∫ x xᵀ dm. With m > 0 its
Schur complement is Σ_c = Σ_o − h hᵀ/m = ½ tr(I_c) 1 − I_c = ∫ (x − c)(x − c)ᵀ dm, whose
eigenvalues d_i = ½(λ_j + λ_k − λ_i) (λ: principal moments of I_c) are the triangle
inequalities. A symmetric 3 × 3 matrix A is positive semidefinite iff the coefficients of its
characteristic polynomial e₁ = tr A, e₂ = ½(tr² A − tr A²), e₃ = det A are all ≥ 0 (its roots are
real; Descartes' rule of signs). So per body the margins

    m,   e₁, e₂, e₃ of m I_c = m I_o − S(h),   e₂, e₃ of m Σ_c = ½ tr(m I_c) 1 − m I_c

are polynomials in θ (degree ≤ 6: smooth everywhere), invariant under rotations of the
body frame, and all ≥ 0 exactly when m ≥ 0, I_c ⪰ 0 and the triangle inequalities hold (all > 0:
strictly consistent). e₁(m Σ_c) = ½ e₁(m I_c) is left out; the I_c group is implied by the Σ_c
group (λ_i = d_j + d_k) and kept so that each violated condition has its own named margin.

Declared uncertainty (``ModelUncertainty``), independent per body: the mass (relative), the centre
of mass c (σ in metres on each body axis, or ``relative`` × the body's size ℓ, ``estimator.spatial.geometry.body_sizes``),
and the distribution of the mass about c, strained: x − c → (1 + ε)(x − c) with ε a random
symmetric strain, isotropic (diagonal σ = ``inertia_rel``/2, off-diagonal σ = ``inertia_rel``/(2√2),
so no frame is preferred), i.e. Σ_c → (1 + ε) Σ_c (1 + ε). Along the principal axes the second
moments d_i (eigenvalues of Σ_c) change by the relative σ ``inertia_rel``; the shears tilt the
principal axes (a rod's axis by an angle ~ ε). A congruence keeps Σ_c ⪰ 0: every draw is a
physical body, and for Σ_c ≻ 0 the ten directions per body are all uncertain (a full-rank prior
for the identification). (Independent relative errors on the principal moments λ_i themselves
are not physical: on a slender body the triangle slack is small (the quadruped leg's shank:
λ_y + λ_z − λ_x = 1.9 % of λ_x), and at 5 % such draws violate the triangle inequality 79 % of
the time on that shank, 21 % on its thigh.) Each λ_i = d_j + d_k gets a relative σ between
``inertia_rel``/√2 and ``inertia_rel``. Linearized: Σ_θ = J diag(σ_p²) Jᵀ, p = [m, c, ε_xx, ε_yy,
ε_zz, ε_xy, ε_xz, ε_yz] (ε in the principal frame R of Σ_c = R diag(d) Rᵀ), with I_c = tr(Σ_c) 1 − Σ_c:

    ∂θ/∂m = [1, c, S(c)],  ∂θ/∂c_a = [0, m e_a, m (2 c_a 1 − e_a cᵀ − c e_aᵀ)],
    ∂I_o/∂ε_aa = 2 d_a (1 − r_a r_aᵀ),  ∂I_o/∂ε_ab = −(d_a + d_b)(r_a r_bᵀ + r_b r_aᵀ)
"""

from __future__ import annotations

import numpy as np

PARAMS = ("m", "mc_x", "mc_y", "mc_z", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
_VECH = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))       # I entries in PARAMS order
PER_BODY_MARGINS = ("mass > 0", "I_c ⪰ 0 (trace)", "I_c ⪰ 0 (2 × 2 minors)", "I_c ⪰ 0 (determinant)",
                    "triangle inequalities (2 × 2 minors of Σ_c)",
                    "triangle inequalities (det Σ_c = Π (λ_j + λ_k − λ_i)/2)")


def unpack(theta):
    """(m (NB,), h (NB, 3), I_o (NB, 3, 3)) of θ (NB·10,)."""
    th = np.asarray(theta, float).reshape(-1, 10)
    Io = np.empty((len(th), 3, 3))
    for k, (i, j) in enumerate(_VECH):
        Io[:, i, j] = Io[:, j, i] = th[:, 4 + k]
    return th[:, 0], th[:, 1:4], Io


def pack(m, h, Io) -> np.ndarray:
    """θ from per-body mass, first moment and inertia about the body origin (inverse of unpack)."""
    m = np.asarray(m, float)
    out = np.empty(m.shape + (10,))
    out[..., 0], out[..., 1:4] = m, h
    for k, (i, j) in enumerate(_VECH):
        out[..., 4 + k] = Io[..., i, j]
    return out.reshape(m.shape[:-1] + (-1,))


def _S(c):
    """S(c) = |c|² 1 − c cᵀ (= [c]×ᵀ[c]×), batched over leading axes."""
    c = np.asarray(c, float)
    return np.einsum("...i,...i->...", c, c)[..., None, None] * np.eye(3) - c[..., :, None] * c[..., None, :]


def _invariants(A):
    """(e₁, e₂, e₃) of symmetric 3 × 3 matrices A (…, 3, 3): the characteristic polynomial's."""
    e1 = np.trace(A, axis1=-2, axis2=-1)
    e2 = 0.5 * (e1 * e1 - np.einsum("...ij,...ji->...", A, A))
    return e1, e2, np.linalg.det(A)


def consistency_margins(theta) -> np.ndarray:
    """Per body [m, e₁, e₂, e₃ (m I_c), e₂, e₃ (m Σ_c)] (module doc), flattened body by body."""
    m, h, Io = unpack(theta)
    mIc = m[:, None, None] * Io - _S(h)
    mSc = 0.5 * np.trace(mIc, axis1=1, axis2=2)[:, None, None] * np.eye(3) - mIc
    a1, a2, a3 = _invariants(mIc)
    _, b2, b3 = _invariants(mSc)
    return np.stack([m, a1, a2, a3, b2, b3], axis=1).ravel()


def margin_names(body_names) -> list[str]:
    return [f"{b}: {p}" for b in body_names for p in PER_BODY_MARGINS]


def physical(theta):
    """Per body (m, c, d, R): mass, centre of mass (body frame), principal second moments about c
    (eigenvalues of Σ_c, ascending) and their axes (columns of R). Needs m > 0."""
    m, h, Io = unpack(theta)
    c = h / m[:, None]
    Ic = Io - m[:, None, None] * _S(c)
    Sc = 0.5 * np.trace(Ic, axis1=1, axis2=2)[:, None, None] * np.eye(3) - Ic
    d, R = np.linalg.eigh(Sc)
    return m, c, d, R


def from_physical(m, c, Sc) -> np.ndarray:
    """θ of bodies (m, c, Σ_c) (leading axes broadcast): I_c = tr(Σ_c) 1 − Σ_c, I_o = I_c + m S(c)."""
    m, c, Sc = (np.asarray(x, float) for x in (m, c, Sc))
    Ic = np.trace(Sc, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) - Sc
    return pack(m, m[..., None] * c, Ic + m[..., None, None] * _S(c))


def pseudo_inertia(theta) -> np.ndarray:
    """J = [[Σ_o, h], [hᵀ, m]] per body (NB, 4, 4), Σ_o = ½ tr(I_o) 1 − I_o (module doc)."""
    m, h, Io = unpack(theta)
    J = np.empty((len(m), 4, 4))
    J[:, :3, :3] = 0.5 * np.trace(Io, axis1=1, axis2=2)[:, None, None] * np.eye(3) - Io
    J[:, :3, 3] = J[:, 3, :3] = h
    J[:, 3, 3] = m
    return J


_SHEARS = ((0, 1), (0, 2), (1, 2))


def sigmas(theta, sizes_m, unc) -> np.ndarray:
    """1σ of the physical errors (NB, 10): [m, c_x, c_y, c_z, ε_xx, ε_yy, ε_zz, ε_xy, ε_xz, ε_yz]."""
    m = unpack(theta)[0]
    sc = np.full(len(m), unc.com_m) if unc.com_m is not None else \
        (unc.relative or 0.0) * np.asarray(sizes_m, float)
    e = 0.5 * unc.inertia_rel
    return np.column_stack([unc.mass_rel * m, sc, sc, sc] + [np.full(len(m), e)] * 3
                           + [np.full(len(m), e / np.sqrt(2.0))] * 3)


def jacobian(theta) -> np.ndarray:
    """∂θ_b/∂p_b (NB, 10, 10), p = [m, c, ε] (module doc)."""
    m, c, d, R = physical(theta)
    NB = len(m)
    J = np.zeros((NB, 10, 10))
    eye = np.eye(3)
    D = np.zeros((NB, 10, 3, 3))                # ∂I_o/∂p
    D[:, 0] = _S(c)
    for a in range(3):
        ea = eye[a]
        dS = 2 * c[:, a, None, None] * eye - ea[None, :, None] * c[:, None, :] - c[:, :, None] * ea[None, None, :]
        D[:, 1 + a] = m[:, None, None] * dS
        J[:, 1 + a, 1 + a] = m
        r = R[:, :, a]
        D[:, 4 + a] = 2 * d[:, a, None, None] * (eye - r[:, :, None] * r[:, None, :])
    for k, (a, b) in enumerate(_SHEARS):
        ra, rb = R[:, :, a], R[:, :, b]
        D[:, 7 + k] = -(d[:, a] + d[:, b])[:, None, None] * (ra[:, :, None] * rb[:, None, :]
                                                             + rb[:, :, None] * ra[:, None, :])
    J[:, 0, 0] = 1.0
    J[:, 1:4, 0] = c
    for k, (i, j) in enumerate(_VECH):
        J[:, 4 + k, :] = D[:, :, i, j]
    return J


def parameter_covariance(theta, sizes_m, unc) -> np.ndarray:
    """Σ_θ = J diag(σ_p²) Jᵀ, block diagonal over bodies (module doc)."""
    J = jacobian(theta)
    s2 = sigmas(theta, sizes_m, unc) ** 2
    NB = len(J)
    out = np.zeros((10 * NB, 10 * NB))
    for b in range(NB):
        out[10 * b:10 * b + 10, 10 * b:10 * b + 10] = (J[b] * s2[b]) @ J[b].T
    return out


def strained(d, R, eps) -> np.ndarray:
    """Σ_c' = R (1 + ε) diag(d) (1 + ε) Rᵀ for strains ε (…, 6) = [xx, yy, zz, xy, xz, yz] in the
    principal frame (always ⪰ 0)."""
    E = np.zeros(eps.shape[:-1] + (3, 3))
    for k in range(3):
        E[..., k, k] = eps[..., k]
    for k, (a, b) in enumerate(_SHEARS):
        E[..., a, b] = E[..., b, a] = eps[..., 3 + k]
    A = np.eye(3) + E
    B = np.einsum("...ij,...jk->...ik", R, A) * np.sqrt(np.maximum(d, 0.0))[..., None, :]
    return np.einsum("...ik,...jk->...ij", B, B)


def draw(theta, sizes_m, unc, rng, n: int | None = None) -> np.ndarray:
    """θ of robots drawn from the declared uncertainty ((n, k), or (k,) for n None): masses
    × max(1 + σ_rel z, 0.2), centres of mass + σ z, the mass distribution strained (module doc;
    every draw consistent)."""
    m, c, d, R = physical(theta)
    NB = len(m)
    shape = (1 if n is None else n, NB)
    z = rng.standard_normal(shape + (10,)) * sigmas(theta, sizes_m, unc)
    m2 = m * np.maximum(1 + z[..., 0] / m, 0.2)
    out = from_physical(m2, c + z[..., 1:4], strained(d, R, z[..., 4:]))
    return out[0] if n is None else out


def parameters_of(pin_model) -> np.ndarray:
    """θ of a pinocchio model: its bodies' dynamic parameters (PARAMS order), body after body."""
    return np.concatenate([np.asarray(pin_model.inertias[j].toDynamicParameters())
                           for j in range(1, pin_model.njoints)])


def parameter_names(body_names) -> tuple:
    """``BODY.m``, ``BODY.mc_x``, … per body (PARAMS order)."""
    return tuple(f"{b}.{p}" for b in body_names for p in PARAMS)
