"""Inertial parameters of the planar chain (``estimator.robot.Robot`` as a ``RobotModel``).

Per link i (mass m, centre of mass r along and s across the axis, inertia I_c about the centre of
mass; docs/conventions.md) and for the base (mass m_b and inertia I_b at the hip):

    θ_i = [m,  h∥ = m r,  h⊥ = m s,  I_o = I_c + m (r² + s²)],     θ_b = [m_b, I_b],
    θ = [θ_b, θ_1, …, θ_N]           (``parameter_names``: base.m, base.I, link1.m, …)

The dynamics are linear in θ. With link i's first moment h_i = h∥ e_i + h⊥ n_i (world frame),
joint point p_i moving at v_i, its linear momentum and its angular momentum about p_i are

    L_i = m v_i + φ̇_i ⊥h_i,        H_i = h_i × v_i + I_o φ̇_i,

so, for the translation rows and for an angle row with origin o (velocity ȯ) that moves links S:

    P_xz = m_b v_b + Σ_i L_i,              P_o = Σ_S [H_i + (p_i − o) × L_i]  (+ I_b θ̇ on the θ row)
    (Cᵀv)_o = −ȯ × Σ_S L_i  (0 on x, z),   G_z = g (m_b + Σ m_i),   G_o = g Σ_S [m_i (p_i − o)_x + h_i,x]

each a sum of (known function of q, v) × (one entry of θ): the regressor Y_P, Y_u = Y_{Cᵀv} − Y_G
(``momentum_regressor``; compiled in estimator.model_kernels, this numpy form is its reference).
"""

from __future__ import annotations

import math

import numpy as np

from userio.errors import InputError

PER_LINK = ("m", "mc_par", "mc_perp", "I_joint")
def parameter_names(n_links: int) -> tuple[str, ...]:
    return ("base.m", "base.I") + tuple(f"link{i}.{p}" for i in range(1, n_links + 1)
                                        for p in PER_LINK)


def parameters(robot) -> np.ndarray:
    """θ of a Robot (module doc)."""
    m, r, s = robot.masses_kg, robot.com_m, robot.com_perp_m
    links = np.stack([m, m * r, m * s, robot.inertias_kgm2 + m * (r * r + s * s)], axis=1)
    return np.concatenate([[robot.base_mass_kg, robot.base_inertia_kgm2], links.ravel()])


def _split(theta, n_links):
    theta = np.asarray(theta, float)
    if theta.shape != (2 + 4 * n_links,):
        raise InputError(f"inertial parameters: expected {2 + 4 * n_links} values, got {theta.shape}")
    return theta[0], theta[1], theta[2:].reshape(n_links, 4)


def with_parameters(robot, theta):
    """The same robot with inertial parameters θ; refuses an inconsistent θ naming why."""
    from dataclasses import replace

    problems = consistency_problems(robot, theta)
    if problems:
        raise InputError(f"inertial parameters of '{robot.name}': {problems[0]}")
    mb, Ib, L = _split(theta, robot.n_links)
    m = L[:, 0]
    r, s = L[:, 1] / m, L[:, 2] / m
    return replace(robot, masses_kg=m.copy(), com_m=r, com_perp_m=s,
                   inertias_kgm2=L[:, 3] - m * (r * r + s * s), base_mass_kg=float(mb),
                   base_inertia_kgm2=float(Ib))


def consistency_margins(robot, theta) -> np.ndarray:
    """Per body, values ≥ 0 exactly when θ is physical: m > 0, m I_c = m I_o − h∥² − h⊥² > 0,
    the centre of mass on its link (0 ≤ r ≤ l, |s| ≤ l); the base: m_b > 0, I_b > 0."""
    mb, Ib, L = _split(theta, robot.n_links)
    m, hp, hq, Io = L.T
    l = robot.lengths_m
    links = np.stack([m, m * Io - hp * hp - hq * hq, hp, l * m - hp, l * m - hq, l * m + hq], axis=1)
    return np.concatenate([[mb, Ib], links.ravel()])


def consistency_lmis(robot, theta) -> list[np.ndarray]:
    """The conditions of ``consistency_margins`` as symmetric matrices affine in θ, each ⪰ 0 exactly
    when its condition holds: per link [[I_o, h∥, h⊥], [h∥, m, 0], [h⊥, 0, m]] (its Schur complement
    is I_o − |h|²/m = I_c), and 1 × 1: m_b, I_b, h∥, l m − h∥, l m − h⊥, l m + h⊥ per link."""
    mb, Ib, L = _split(theta, robot.n_links)
    m, hp, hq, Io = L.T
    l = robot.lengths_m
    S = np.zeros((robot.n_links, 3, 3))
    S[:, 0, 0], S[:, 1, 1], S[:, 2, 2] = Io, m, m
    S[:, 0, 1] = S[:, 1, 0] = hp
    S[:, 0, 2] = S[:, 2, 0] = hq
    scalars = np.concatenate([[mb, Ib], np.stack([hp, l * m - hp, l * m - hq, l * m + hq], 1).ravel()])
    return [S, scalars[:, None, None]]


def margin_names(n_links: int) -> list[str]:
    """What each entry of ``consistency_margins`` bounds."""
    per = ("mass > 0", "inertia about the COM > 0", "COM along the axis ≥ 0",
           "COM along the axis ≤ length", "COM across the axis ≤ length", "COM across the axis ≥ −length")
    return ["base mass > 0", "base inertia > 0"] + [f"link {i}: {p}" for i in range(1, n_links + 1)
                                                    for p in per]


def consistency_problems(robot, theta) -> list[str]:
    """What makes θ unphysical, one message per violated condition ([] when consistent)."""
    mb, Ib, L = _split(theta, robot.n_links)
    out = []
    if not np.all(np.isfinite(theta)):
        return ["a parameter is not finite"]
    if mb <= 0:
        out.append(f"base mass {mb:.6g} kg ≤ 0")
    if Ib <= 0:
        out.append(f"base inertia {Ib:.6g} kg·m² ≤ 0")
    for i, (m, hp, hq, Io) in enumerate(L, start=1):
        if m <= 0:
            out.append(f"link {i}: mass {m:.6g} kg ≤ 0")
            continue
        r, s, l = hp / m, hq / m, robot.lengths_m[i - 1]
        Ic = Io - m * (r * r + s * s)
        if Ic <= 0:
            out.append(f"link {i}: inertia about the centre of mass {Ic:.6g} kg·m² ≤ 0")
        if not 0 <= r <= l:
            out.append(f"link {i}: centre of mass {r:.6g} m along the axis, off the link [0, {l:g}] m")
        if abs(s) > l:
            out.append(f"link {i}: centre of mass {s:.6g} m across the axis, beyond the link's length")
    return out


def parameter_covariance(robot, unc) -> np.ndarray:
    """Σ_θ = J diag(σ_p²) Jᵀ for independent physical errors p = (m, r, s, I_c) per link (σ: the
    relative mass and inertia, the COM σ in metres, or relative × length) and (m_b, I_b)."""
    n = robot.n_links
    S = np.zeros((2 + 4 * n, 2 + 4 * n))
    S[0, 0] = (unc.mass_rel * robot.base_mass_kg) ** 2
    S[1, 1] = (unc.inertia_rel * robot.base_inertia_kgm2) ** 2
    for i in range(n):
        m, r, s, Ic = (robot.masses_kg[i], robot.com_m[i], robot.com_perp_m[i],
                       robot.inertias_kgm2[i])
        sc = unc.com_m if unc.com_m is not None else (unc.relative or 0.0) * robot.lengths_m[i]
        sig = np.array([unc.mass_rel * m, sc, sc, unc.inertia_rel * Ic])
        J = np.array([[1, 0, 0, 0], [r, m, 0, 0], [s, 0, m, 0],
                      [r * r + s * s, 2 * m * r, 2 * m * s, 1]], float)
        k = slice(2 + 4 * i, 6 + 4 * i)
        S[k, k] = (J * sig ** 2) @ J.T
    return S


def model_covariance(robot):
    """(Σ_θ, source): the [identification] covariance, else the declared [model_uncertainty]."""
    ident = robot.identification
    if ident is not None:
        logs = ", ".join(str(g.get("path", "?")) for g in ident.get("logs", [])) or "its logs"
        return np.asarray(ident["covariance"], float), f"identification of {robot.name} from {logs}"
    if robot.model_uncertainty is not None:
        unc = robot.model_uncertainty
        return parameter_covariance(robot, unc), f"declared model uncertainty: {unc.describe()}"
    return None, "the robot file is not identified and declares no [model_uncertainty]"


def perturbed(robot, unc, seed: int):
    """A robot whose inertial data differ from ``robot`` by one draw of the declared physical
    uncertainty (masses, inertias × (1 + σ_rel z), floored at 20 %; COM + σ z, kept on the link);
    no identification or declared uncertainty carried over."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    n = robot.n_links
    z = rng.standard_normal((n, 4))
    zb = rng.standard_normal(2)
    sc = np.full(n, unc.com_m) if unc.com_m is not None else (unc.relative or 0.0) * robot.lengths_m
    grow = lambda x, rel, zz: x * np.maximum(1 + rel * zz, 0.2)     # noqa: E731
    return replace(robot, masses_kg=grow(robot.masses_kg, unc.mass_rel, z[:, 0]),
                   com_m=np.clip(robot.com_m + sc * z[:, 1], 0.0, robot.lengths_m),
                   com_perp_m=np.clip(robot.com_perp_m + sc * z[:, 2], -robot.lengths_m, robot.lengths_m),
                   inertias_kgm2=grow(robot.inertias_kgm2, unc.inertia_rel, z[:, 3]),
                   base_mass_kg=float(grow(robot.base_mass_kg, unc.mass_rel, zb[0])),
                   base_inertia_kgm2=float(grow(robot.base_inertia_kgm2, unc.inertia_rel, zb[1])),
                   name=f"{robot.name}_perturbed_{seed}", model_uncertainty=None, identification=None)


# ----------------------------------------------------------------------------- the regressor
def momentum_regressor(robot, q, v):
    """(Y_P, Y_u), each (T, N+3, n_θ), floating coordinates (module doc): compiled when numba is
    available, else ``regressor_numpy``."""
    from estimator import model_kernels

    q = np.atleast_2d(np.asarray(q, float))
    v = np.atleast_2d(np.asarray(v, float))
    if model_kernels.available():
        return model_kernels.momentum_regressor(robot, q, v)
    return regressor_numpy(robot, q, v)


def regressor_numpy(robot, q, v):
    """The regressor in numpy: a loop over links and angle rows, vectorized over samples."""
    q = np.atleast_2d(np.asarray(q, float))
    v = np.atleast_2d(np.asarray(v, float))
    T, n = q.shape
    N = n - 3
    g = robot.gravity_m_per_s2
    l = robot.lengths_m
    YP = np.zeros((T, n, 2 + 4 * N))
    Yu = np.zeros_like(YP)
    phi = q[:, 2:3] + np.cumsum(q[:, 3:], axis=1)
    w = v[:, 2:3] + np.cumsum(v[:, 3:], axis=1)
    sn, cs = np.sin(phi), np.cos(phi)
    ex, ez, nx, nz = sn, -cs, cs, sn
    px = np.concatenate([np.zeros((T, 1)), np.cumsum(l * ex, axis=1)], axis=1)
    pz = np.concatenate([np.zeros((T, 1)), np.cumsum(l * ez, axis=1)], axis=1)
    vx = v[:, :1] + np.concatenate([np.zeros((T, 1)), np.cumsum(l * w * nx, axis=1)], axis=1)
    vz = v[:, 1:2] + np.concatenate([np.zeros((T, 1)), np.cumsum(l * w * nz, axis=1)], axis=1)
    YP[:, 0, 0], YP[:, 1, 0], YP[:, 2, 1] = v[:, 0], v[:, 1], v[:, 2]
    Yu[:, 1, 0] = -g
    for i in range(N):
        c = 2 + 4 * i
        Lx = [vx[:, i], w[:, i] * nx[:, i], -w[:, i] * ex[:, i], 0.0]
        Lz = [vz[:, i], w[:, i] * nz[:, i], -w[:, i] * ez[:, i], 0.0]
        H = [0.0, ex[:, i] * vz[:, i] - ez[:, i] * vx[:, i],
             nx[:, i] * vz[:, i] - nz[:, i] * vx[:, i], w[:, i]]
        for j in range(4):
            YP[:, 0, c + j] = Lx[j]
            YP[:, 1, c + j] = Lz[j]
        Yu[:, 1, c] = -g
        for a in range(i + 2):                 # θ row (a = 0) and joint rows q_1 … q_{i+1}
            o = max(a - 1, 0)
            dx, dz = px[:, i] - px[:, o], pz[:, i] - pz[:, o]
            for j in range(4):
                YP[:, 2 + a, c + j] = H[j] + dx * Lz[j] - dz * Lx[j]
                Yu[:, 2 + a, c + j] = -(vx[:, o] * Lz[j] - vz[:, o] * Lx[j])
            Yu[:, 2 + a, c] -= g * dx
            Yu[:, 2 + a, c + 1] -= g * ex[:, i]
            Yu[:, 2 + a, c + 2] -= g * nx[:, i]
    return YP, Yu


# ----------------------------------------------------------------------------- robot TOML tables
def read_uncertainty(table):
    """[model_uncertainty] (a validated userio.schema.robot.ModelUncertaintyTable) → the
    ModelUncertainty: ``relative`` fills what the file leaves out."""
    from estimator.model import ModelUncertainty

    rel = table.relative
    pick = lambda v: rel if v is None else v            # noqa: E731
    return ModelUncertainty(mass_rel=pick(table.mass_rel), inertia_rel=pick(table.inertia_rel),
                            com_m=table.com_m, relative=rel)


def read_identification(model, table, where: str) -> dict:
    """[identification] (a validated userio.schema.robot.IdentificationTable) checked against a
    RobotModel (the planar Robot, a URDF robot's UrdfModel): its parameter names and values must be
    the model's (``parameter_names``, ``parameters()``), its covariance (n_θ × n_θ) symmetric
    positive semi-definite."""
    err = lambda key, msg: InputError(f"{where}: identification.{key}: {msg}")   # noqa: E731
    want = list(model.parameter_names)
    if table.parameter_names != want:
        raise err("parameter_names", f"expected {want} (this robot's {len(want)} inertial "
                  f"parameters), got {table.parameter_names!r}")
    k = len(want)
    theta = np.asarray(table.parameters, float)
    if theta.size != k:
        raise err("parameters", f"expected {k} numbers, got {theta.size}")
    ref = np.asarray(model.parameters(), float)
    scale = np.abs(ref) + 1e-12
    if np.any(np.abs(theta - ref) > 1e-6 * scale):
        j = int(np.argmax(np.abs(theta - ref) / scale))
        raise err("parameters", f"{want[j]} = {theta[j]:.9g} differs from the file's inertial "
                  f"data ({ref[j]:.9g}): edited after identification? Identify again")
    if len(table.covariance) != k or any(len(r) != k for r in table.covariance):
        raise err("covariance", f"expected a {k} × {k} matrix of numbers")
    C = np.asarray(table.covariance, float)
    tol = 1e-9 * max(float(np.abs(C).max()), 1e-300)
    if np.abs(C - C.T).max() > tol or np.linalg.eigvalsh(0.5 * (C + C.T)).min() < -1e-6 * np.abs(C).max():
        raise err("covariance", "must be symmetric positive semi-definite")
    out = {key: v for key, v in table.model_dump().items() if v is not None}
    out["parameters"] = theta.tolist()
    out["covariance"] = 0.5 * (C + C.T)
    return out


def read_tables(robot, file, source: str, model=None):
    """The robot (a dataclass with ``model_uncertainty`` and ``identification`` fields) with the
    validated file's (``file``: userio.schema) tables; the identification checked against
    ``model`` (default: the robot itself)."""
    from dataclasses import replace

    unc = None if file.model_uncertainty is None else read_uncertainty(file.model_uncertainty)
    ident = None if file.identification is None else read_identification(
        robot if model is None else model, file.identification, source)
    return replace(robot, model_uncertainty=unc, identification=ident)


def robot_toml(robot, identification: dict | None = None, header: str = "") -> str:
    """A robot TOML (docs/conventions.md) of ``robot``, with its declared uncertainty and an
    [identification] table; numbers with 12 significant digits."""
    num = lambda x: f"{float(x):.12g}"                                     # noqa: E731
    vec = lambda v: "[" + ", ".join(num(x) for x in v) + "]"               # noqa: E731
    L = [header.rstrip()] if header else []
    L += [f"name = {_toml_str(robot.name)}", f'base = "{"floating" if robot.floating else "fixed"}"',
          f"gravity_m_per_s2 = {num(robot.gravity_m_per_s2)}",
          f"friction_coefficient = {num(robot.friction_coefficient)}", "",
          "[base_body]", f"mass_kg = {num(robot.base_mass_kg)}",
          f"inertia_kgm2 = {num(robot.base_inertia_kgm2)}", "",
          "[base_mount]", f"stiffness = {vec(robot.base_stiffness)}",
          f"damping = {vec(robot.base_damping)}", ""]
    for i in range(robot.n_links):
        L += ["[[link]]", f"length_m = {num(robot.lengths_m[i])}", f"com_m = {num(robot.com_m[i])}",
              f"com_perp_m = {num(robot.com_perp_m[i])}", f"mass_kg = {num(robot.masses_kg[i])}",
              f"inertia_kgm2 = {num(robot.inertias_kgm2[i])}", ""]
    unc = robot.model_uncertainty
    if unc is not None:
        L += ["[model_uncertainty]", f"mass_rel = {num(unc.mass_rel)}",
              f"inertia_rel = {num(unc.inertia_rel)}"]
        L += [f"com_m = {num(unc.com_m)}"] if unc.com_m is not None else \
            [f"relative = {num(unc.relative or 0.0)}"]
        L.append("")
    if identification:
        L += ["[identification]"] + toml_lines(identification, "identification")
    return "\n".join(L).rstrip() + "\n"


def toml_lines(data: dict, table: str = "") -> list[str]:
    """TOML lines of ``data`` (one level of sub-tables and lists of tables) inside ``table``:
    its plain keys, then ``[table.k]`` per dict, then ``[[table.k]]`` per list of dicts."""
    pre = f"{table}." if table else ""
    L = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict) and not _is_table_list(v)]
    for k, v in data.items():
        if isinstance(v, dict):
            L += ["", f"[{pre}{k}]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
    for k, v in data.items():
        if _is_table_list(v):
            for item in v:
                L += ["", f"[[{pre}{k}]]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items()]
    return L


def _is_table_list(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _toml_str(s: str) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        x = float(v)
        return f"{x:.12g}" if math.isfinite(x) else ("nan" if x != x else ("inf" if x > 0 else "-inf"))
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        if len(v) and isinstance(v[0], (list, tuple, np.ndarray)):
            return "[\n  " + ",\n  ".join(_toml_value(x) for x in v) + ",\n]"
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if v is None:
        return '""'
    raise TypeError(f"cannot write {type(v).__name__} to TOML")
