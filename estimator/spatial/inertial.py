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

are polynomials in θ (degree ≤ 6: smooth everywhere, for SLSQP), invariant under rotations of the
body frame, and all ≥ 0 exactly when m ≥ 0, I_c ⪰ 0 and the triangle inequalities hold (all > 0:
strictly consistent). e₁(m Σ_c) = ½ e₁(m I_c) is left out; the I_c group is implied by the Σ_c
group (λ_i = d_j + d_k) and kept so that each violated condition has its own named margin.

Declared uncertainty (``ModelUncertainty``), independent per body: the mass (relative), the centre
of mass c (σ in metres on each body axis, or ``relative`` × the body's size ℓ, ``body_sizes``),
and the principal second moments d_i of the mass about c (relative, about the fixed principal
axes of I_c): d_i ≥ 0 is exactly consistency, so every draw is a physical body. (Independent
relative errors on the principal moments λ_i themselves are not: on a slender body the triangle
slack is small (the quadruped leg's shank: λ_y + λ_z − λ_x = 1.9 % of λ_x), and at 5 % such draws
violate the triangle inequality 79 % of the time on that shank, 21 % on its thigh.) A relative error ε on d gives λ_i a relative σ of
ε √(d_j² + d_k²)/(d_j + d_k) ∈ [ε/√2, ε]. Linearized: Σ_θ = J diag(σ_p²) Jᵀ with

    ∂θ/∂m = [1, c, S(c)],  ∂θ/∂c_a = [0, m e_a, m (2 c_a 1 − e_a cᵀ − c e_aᵀ)],  ∂θ/∂d_i = [0, 0, 1 − r_i r_iᵀ]

(r_i the principal axis of d_i; I_c = Σ_i d_i (1 − r_i r_iᵀ)).
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


def from_physical(m, c, d, R) -> np.ndarray:
    """θ of bodies (m, c, d, R) (leading axes broadcast): I_c = Σ_i d_i (1 − r_i r_iᵀ)."""
    m, c, d, R = (np.asarray(x, float) for x in (m, c, d, R))
    Ic = d.sum(-1)[..., None, None] * np.eye(3) - np.einsum("...ik,...k,...jk->...ij", R, d, R)
    return pack(m, m[..., None] * c, Ic + m[..., None, None] * _S(c))


def sigmas(theta, sizes_m, unc) -> np.ndarray:
    """1σ of the physical errors (NB, 7): [m, c_x, c_y, c_z, d_1, d_2, d_3]."""
    m, _, d, _ = physical(theta)
    sc = np.full(len(m), unc.com_m) if unc.com_m is not None else \
        (unc.relative or 0.0) * np.asarray(sizes_m, float)
    return np.column_stack([unc.mass_rel * m, sc, sc, sc, unc.inertia_rel * np.abs(d)])


def jacobian(theta) -> np.ndarray:
    """∂θ_b/∂p_b (NB, 10, 7), p = [m, c, d] (module doc)."""
    m, c, d, R = physical(theta)
    NB = len(m)
    J = np.zeros((NB, 10, 7))
    eye = np.eye(3)
    D = np.zeros((NB, 7, 3, 3))                 # ∂I_o/∂p
    D[:, 0] = _S(c)
    for a in range(3):
        ea = eye[a]
        dS = 2 * c[:, a, None, None] * eye - ea[None, :, None] * c[:, None, :] - c[:, :, None] * ea[None, None, :]
        D[:, 1 + a] = m[:, None, None] * dS
        J[:, 1 + a, 1 + a] = m
    for i in range(3):
        r = R[:, :, i]
        D[:, 4 + i] = eye - r[:, :, None] * r[:, None, :]
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


def draw(theta, sizes_m, unc, rng, n: int | None = None) -> np.ndarray:
    """θ of robots drawn from the declared uncertainty ((n, k), or (k,) for n None): masses and
    second moments × max(1 + σ_rel z, 0.2), centres of mass + σ z (every draw consistent)."""
    m, c, d, R = physical(theta)
    NB = len(m)
    shape = (1 if n is None else n, NB)
    sig = sigmas(theta, sizes_m, unc)
    z = rng.standard_normal(shape + (7,))
    m2 = m * np.maximum(1 + unc.mass_rel * z[..., 0], 0.2)
    c2 = c + sig[:, 1:4] * z[..., 1:4]
    d2 = d * np.maximum(1 + unc.inertia_rel * z[..., 4:], 0.2)
    out = from_physical(m2, c2, d2, np.broadcast_to(R, shape + (3, 3)))
    return out[0] if n is None else out


def body_sizes(robot, tree) -> np.ndarray:
    """ℓ per body (m): the length of its segment (estimator.spatial.geometry: body origin to the
    farthest child joint or fixed child frame, else twice the centre of mass), at least
    √(tr I_c / m) (√2 × the RMS distance of its mass from the centre of mass: a ball's radius)."""
    from estimator.spatial.geometry import body_surfaces

    seg = np.array([np.linalg.norm(s.segment[1] - s.segment[0]) for s in body_surfaces(robot, tree)])
    gyr = np.sqrt(np.trace(tree.Ic, axis1=1, axis2=2) / np.maximum(tree.mass, 1e-300))
    return np.maximum(seg, gyr)
