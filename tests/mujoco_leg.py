"""A test-only simulator of the planar leg that shares no code with estimator.sim: MuJoCo.

``mujoco_log(robot, ...)`` writes the robot into an MJCF (floating base on slide x, slide z and a
hinge, each with the mount's spring and damper; one hinge per link; centres of mass off the link
axis at (com_perp_m, 0, −com_m) in the joint frame; no contacts), servos the joints with a PD
law on a sum of sines evaluated every MuJoCo step (RK4 at 20 kHz), applies pokes as
``xfrc_applied`` and samples at 1 kHz: the state, the servo torques and the mount's wrench, each
the instantaneous value at the sample time, then seeded white sensor noise. Frames: our angles
are counter-clockwise in x–z (x right, z up), a rotation about −y, so every hinge axis is
(0, −1, 0) and a link hangs along −z at zero angle (docs/conventions.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class MjPoke:
    link: int
    alpha: float
    force_N: tuple          # (Fx, Fz)
    t_on_s: float
    t_off_s: float


def mjcf(robot, kp: float, kd: float, pokes=(), timestep: float = 5e-5) -> str:
    """The MJCF text of a planar chain on a floating base (module doc): joint servos as general
    actuators force = act − kp q − kd q̇ with an integrator activation (ȧ = ctrl); per poke a site on its link and two actuators applying
    world-frame x and z forces there (site transmission with the world's ``origin`` as refsite)."""
    K, D = robot.base_stiffness, robot.base_damping
    g = robot.gravity_m_per_s2
    Ib = robot.base_inertia_kgm2
    base_joints = (f'<joint name="x" type="slide" axis="1 0 0" stiffness="{K[0]}" damping="{D[0]}"/>'
                   f'<joint name="z" type="slide" axis="0 0 1" stiffness="{K[1]}" damping="{D[1]}"/>'
                   f'<joint name="theta" type="hinge" axis="0 -1 0" stiffness="{K[2]}" damping="{D[2]}"/>')
    body = ""
    close = ""
    offset = 0.0
    for i in range(robot.n_links):
        I = robot.inertias_kgm2[i]
        sites = "".join(f'<site name="poke{j}" pos="0 0 {-p.alpha * robot.lengths_m[i]:.17g}"/>'
                        for j, p in enumerate(pokes) if p.link == i + 1)
        body += (f'<body name="link{i + 1}" pos="0 0 {-offset:.17g}">'
                 f'<joint name="q{i + 1}" type="hinge" axis="0 -1 0"/>'
                 f'<inertial pos="{robot.com_perp_m[i]:.17g} 0 {-robot.com_m[i]:.17g}" '
                 f'mass="{robot.masses_kg[i]:.17g}" diaginertia="{I:.17g} {I:.17g} {I:.17g}"/>{sites}')
        close += "</body>"
        offset = robot.lengths_m[i]
    acts = "".join(f'<general joint="q{i + 1}" gear="1" dyntype="integrator" gainprm="1" '
                   f'biastype="affine" biasprm="0 {-kp:.17g} {-kd:.17g}"/>'
                   for i in range(robot.n_links))
    acts += "".join(f'<general site="poke{j}" refsite="origin" gear="1 0 0 0 0 0"/>'
                    f'<general site="poke{j}" refsite="origin" gear="0 0 1 0 0 0"/>'
                    for j in range(len(pokes)))
    return f"""<mujoco model="{robot.name}">
  <option timestep="{timestep}" integrator="RK4" gravity="0 0 {-g}">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <site name="origin" pos="0 0 0"/>
    <body name="base">{base_joints}
      <inertial pos="0 0 0" mass="{robot.base_mass_kg:.17g}" diaginertia="{Ib:.17g} {Ib:.17g} {Ib:.17g}"/>
      {body}{close}
    </body>
  </worldbody>
  <actuator>{acts}</actuator>
</mujoco>"""


def mujoco_log(robot, q0, duration_s, *, amplitude=None, frequency_Hz=None, phase=None,
               kp=500.0, kd=10.0, pokes=(), rate_Hz=1000.0, timestep=5e-5, tau_sigma=0.0,
               ft_sigma=(0.0, 0.0, 0.0), seed=0):
    """(SensorLog, truth dict) of a MuJoCo run (module doc). q_d(t) = q0 + Σ_h A sin(2π f t + φ)
    per joint (arrays (N, H), or None to hold q0); the leg starts at q_d(0), q̇_d(0), base at rest.

    The servo is MuJoCo's general actuator force = a − K_P q − K_D q̇ whose activation a (an
    integrator, ȧ = ctrl) is the reference force K_P q_d + K_D q̇_d: ctrl is its secant over each
    step, so a is exact at every step and linear inside it (a reference held over a step would
    be a sawtooth that the joint's fast velocity loop, K_D/I ≈ 3·10⁴ s⁻¹, shows in q̇). The
    feedback is continuous inside RK4's stages; the logged torque is the servo law at the sample
    time. The whole run is one ``mujoco.rollout`` call (open-loop controls, no Python per step)."""
    import mujoco
    from mujoco import rollout

    from estimator.log import SensorLog

    N = robot.n_links
    model = mujoco.MjModel.from_xml_string(mjcf(robot, kp, kd, pokes, timestep))
    data = mujoco.MjData(model)
    q0 = np.asarray(q0, float)
    if amplitude is None:
        A = f = ph = np.zeros((N, 1))
    else:
        A, f, ph = (np.atleast_2d(np.asarray(x, float)) for x in (amplitude, frequency_Hz, phase))
    w = 2 * math.pi * f
    per = int(round(1.0 / (rate_Hz * timestep)))
    T = int(math.floor(duration_s * rate_Hz + 1e-9)) + 1
    n_steps = (T - 1) * per
    ts = np.arange(n_steps + 1) * timestep

    def reference(tt):
        arg = w[None] * tt[:, None, None] + ph[None]
        return q0 + np.sum(A * np.sin(arg), axis=2), np.sum(A * w * np.cos(arg), axis=2)

    qd, dqd = reference(ts)                                        # (steps, N)
    act = kp * qd + kd * dqd                 # the servo's reference force, the actuator's state
    ctrl = np.zeros((n_steps + 1, model.nu))
    ctrl[:-1, :N] = np.diff(act, axis=0) / timestep                # its secant rate per step
    for j, p in enumerate(pokes):
        on = (ts >= p.t_on_s) & (ts < p.t_off_s)
        ctrl[on, N + 2 * j] = p.force_N[0]
        ctrl[on, N + 2 * j + 1] = p.force_N[1]
    data.qpos[3:] = qd[0]
    data.qvel[3:] = dqd[0]
    data.act[:N] = act[0]
    mujoco.mj_forward(model, data)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, x0, spec)
    states, _ = rollout.rollout(model, data, x0[None], ctrl[None, :n_steps], nstep=n_steps)
    # FULLPHYSICS state: [time, qpos, qvel, act, ...]; row k holds the state after step k + 1
    traj = np.concatenate([x0[None], states[0]])[::per]
    nq = model.nq
    q = traj[:, 1:1 + nq].copy()
    dq = traj[:, 1 + nq:1 + 2 * nq].copy()
    t_log = np.arange(T) / rate_Hz
    assert np.allclose(traj[:, 0], t_log, atol=1e-9)
    tau = kp * (qd[::per] - q[:, 3:]) + kd * (dqd[::per] - dq[:, 3:])   # the servo law at t
    K, D = np.asarray(robot.base_stiffness, float), np.asarray(robot.base_damping, float)
    W = -K * q[:, :3] - D * dq[:, :3]
    truth = {"t": t_log, "link": np.zeros(T, int), "alpha": np.full(T, np.nan),
             "Fx": np.zeros(T), "Fz": np.zeros(T), "px": np.full(T, np.nan), "pz": np.full(T, np.nan)}
    for j, p in enumerate(pokes):
        on = np.flatnonzero((t_log >= p.t_on_s - 1e-12) & (t_log < p.t_off_s - 1e-12))
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"poke{j}")
        for i in on:
            data.qpos[:] = q[i]
            mujoco.mj_kinematics(model, data)
            truth["px"][i], truth["pz"][i] = data.site_xpos[site][0], data.site_xpos[site][2]
        truth["link"][on], truth["alpha"][on] = p.link, p.alpha
        truth["Fx"][on], truth["Fz"][on] = p.force_N
    rng = np.random.default_rng(seed)
    tau_m = tau + tau_sigma * rng.standard_normal(tau.shape)
    W_m = W + np.asarray(ft_sigma, float) * rng.standard_normal(W.shape)
    log = SensorLog(t=t_log, q=q, dq=dq, tau_Nm=tau_m, wrench=W_m, floating=True,
                    source=f"mujoco:{robot.name}")
    return log, truth
