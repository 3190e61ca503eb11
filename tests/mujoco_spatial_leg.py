"""An independent generator of 3-D leg logs: MuJoCo loads the URDF itself (its own importer), the
base rides six spring-damper joints (a test rig's mount), PD servos on motors, pokes through
``xfrc_applied``, MuJoCo's own force/torque sensors at the FT frame. Written to a CSV with the
column contract of docs/conventions.md by pandas here (not by torquebench's writer), with its
truth, timing and noise side files. Test-only (mujoco is a test dependency)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np


def mjcf_from_urdf(urdf_path, stiffness=(2e4, 2e4, 2e4, 800, 800, 800),
                   damping=(150, 150, 150, 4, 4, 4), mount_xyz=(0, 0, 0.6), ft_frame="ft_sensor",
                   floating=True, rigid=False) -> str:
    import mujoco

    text = Path(urdf_path).read_text()
    head = text.index(">", text.index("<robot")) + 1
    text = (text[:head] + '<mujoco><compiler discardvisual="true" fusestatic="false" '
            'balanceinertia="false"/></mujoco>' + text[head:])
    m = mujoco.MjModel.from_xml_string(text)
    tmp = Path("/tmp") / f"mj_{abs(hash(text))}.xml"
    mujoco.mj_saveLastXML(str(tmp), m)
    root = ET.fromstring(tmp.read_text())
    tmp.unlink()
    root.insert(0, ET.fromstring('<option timestep="0.0001" integrator="RK4"/>'))
    world = root.find("worldbody")
    base = world.find("body")
    base.set("pos", " ".join(map(str, mount_xyz)))
    if floating:
        for i, (ax, kind) in enumerate(zip(["1 0 0", "0 1 0", "0 0 1"] * 2, ["slide"] * 3 + ["hinge"] * 3)):
            j = ET.Element("joint", name=f"mount{i}", type=kind, axis=ax, pos="0 0 0",
                           stiffness=str(stiffness[i]), damping=str(damping[i]))
            base.insert(0, j)
    if rigid:                                 # every joint welded (a static check)
        for parent in list(root.iter()):
            for j in list(parent.findall("joint")):
                parent.remove(j)
    for j in root.iter("joint"):
        j.attrib.pop("actuatorfrcrange", None)
        j.attrib.pop("range", None)
    ft = next(b for b in base.iter("body") if b.get("name") == ft_frame)
    # the sensor measures the interaction of the site's body with its parent: the site sits on
    # the base itself, at the FT frame's pose (a child of the base in the URDF)
    ET.SubElement(base, "site", name="ft", pos=ft.get("pos", "0 0 0"), quat=ft.get("quat", "1 0 0 0"))
    ET.SubElement(base, "site", name="base_origin", pos="0 0 0")
    names = [j.get("name") for j in root.iter("joint") if not j.get("name").startswith("mount")]
    act = ET.SubElement(root, "actuator") if names else ET.Element("actuator")
    for n in names:
        ET.SubElement(act, "motor", name=n, joint=n, gear="1")
    sens = ET.SubElement(root, "sensor")
    ET.SubElement(sens, "force", name="ft_force", site="ft")
    ET.SubElement(sens, "torque", name="ft_torque", site="ft")
    ET.SubElement(sens, "framelinvel", name="base_v", objtype="site", objname="base_origin")
    ET.SubElement(sens, "gyro", name="base_w", site="base_origin")
    return ET.tostring(root, encoding="unicode")


def simulate_mujoco(urdf_path, out_csv, *, q0, pokes, duration_s=1.0, rate_Hz=1000.0,
                    kp=60.0, kd=1.5, amplitude=None, frequency_Hz=1.0, noise=None, seed=0,
                    floating=True, sensed=None):
    """pokes: [(link, point in the link frame, force (world), t_on, t_off)]; noise: (τ σ,
    force σ, moment σ) or None. Writes out_csv, .truth.csv, .timing.toml, (.noise.toml)."""
    import mujoco
    import pandas as pd

    global SENSOR_SIGN
    SENSOR_SIGN = sensor_sign(urdf_path)
    model = mujoco.MjModel.from_xml_string(mjcf_from_urdf(urdf_path, floating=floating))
    data = mujoco.MjData(model)
    joints = [model.joint(i).name for i in range(model.njnt) if not model.joint(i).name.startswith("mount")]
    qadr = np.array([model.joint(n).qposadr[0] for n in joints])
    vadr = np.array([model.joint(n).dofadr[0] for n in joints])
    base = model.body("base").id
    q0 = np.asarray(q0, float)
    amp = np.zeros(len(joints)) if amplitude is None else np.asarray(amplitude, float)
    data.qpos[qadr] = q0
    w = 2 * math.pi * frequency_Hz

    def ref(t):
        x = min(t / 0.25, 1.0)
        e, de = x * x * (3 - 2 * x), (6 * x * (1 - x) / 0.25 if x < 1 else 0.0)
        return q0 + e * amp * np.sin(w * t), amp * (de * np.sin(w * t) + e * w * np.cos(w * t))

    # settle on the springs under gravity with the servos holding q0 (no poke), then log
    sub = int(round(1.0 / (rate_Hz * model.opt.timestep)))
    for _ in range(int(1.5 / model.opt.timestep)):
        data.ctrl[:] = kp * (q0 - data.qpos[qadr]) - kd * data.qvel[vadr]
        mujoco.mj_step(model, data)
    data.qvel[:] = 0.0
    T = int(round(duration_s * rate_Hz)) + 1
    ft_site = model.site("ft").id
    rows, truth = [], []
    vel = np.zeros(6)
    for k in range(T):
        t = k / rate_Hz
        for i in range(sub):
            ts = t + i * model.opt.timestep
            qr, dqr = ref(ts)
            data.ctrl[:] = kp * (qr - data.qpos[qadr]) + kd * (dqr - data.qvel[vadr])
            data.xfrc_applied[:] = 0.0
            active = None
            for link, p_local, F, t_on, t_off in pokes:
                if t_on <= ts < t_off:
                    b = model.body(link).id
                    p = data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(p_local, float)
                    data.xfrc_applied[b, :3] = F
                    data.xfrc_applied[b, 3:] = np.cross(p - data.xipos[b], F)
                    active = (link, p_local, p, F)
            if i == 0:
                mujoco.mj_forward(model, data)
                mujoco.mj_rnePostConstraint(model, data)
                sample = _sample(model, data, base, ft_site, qadr, vadr, vel)
                rows.append((t, *sample))
                if active is None:
                    truth.append((t, "", *[np.nan] * 9))
                else:
                    link, pl, p, F = active
                    truth.append((t, link, *pl, *p, *F))
            if k == T - 1:
                break
            mujoco.mj_step(model, data)
    cols = (["t", "x", "y", "z", "qx", "qy", "qz", "qw"] + [f"q_{n}" for n in joints]
            + ["vx", "vy", "vz", "wx", "wy", "wz"] + [f"dq_{n}" for n in joints]
            + [f"tau_{n}" for n in joints] + ["Fx", "Fy", "Fz", "Mx", "My", "Mz"])
    frame = pd.DataFrame(rows, columns=cols)
    if not floating:
        frame = frame.drop(columns=["x", "y", "z", "qx", "qy", "qz", "qw", "vx", "vy", "vz", "wx", "wy", "wz"])
    if sensed is not None:
        frame = frame.drop(columns=[f"tau_{n}" for n in joints if n not in sensed])
    if noise is not None:
        rng = np.random.default_rng(seed)
        tau_cols = [c for c in frame.columns if c.startswith("tau_")]
        frame[tau_cols] += rng.normal(size=(T, len(tau_cols))) * noise[0]
        frame[["Fx", "Fy", "Fz"]] += rng.normal(size=(T, 3)) * noise[1]
        frame[["Mx", "My", "Mz"]] += rng.normal(size=(T, 3)) * noise[2]
    out_csv = Path(out_csv)
    frame.to_csv(out_csv, index=False, float_format="%.17g")
    pd.DataFrame(truth, columns=["t", "link", "lx", "ly", "lz", "px", "py", "pz", "Fx", "Fy", "Fz"]).to_csv(
        out_csv.with_name(out_csv.stem + ".truth.csv"), index=False)
    out_csv.with_name(out_csv.stem + ".timing.toml").write_text('[timing]\ndefault = "instant"\n')
    if noise is not None:
        out_csv.with_name(out_csv.stem + ".noise.toml").write_text(
            f"[noise]\ntorque_sigma_Nm = [{noise[0]}]\nft_sigma = [{noise[1]}, {noise[2]}]\n")
    return out_csv


def _sample(model, data, base, ft_site, qadr, vadr, vel):
    """(base pose, joints, base twist, joint rates, actuator torques, FT wrench ON the robot).

    MuJoCo's force/torque sensors give the interaction between the site's body (the base) and
    its parent (the rig) in the site frame; checked by ``sensor_sign`` (at rest the rig holds the
    leg up: +M g along the world z) and used with that sign."""
    import mujoco

    pos = data.xpos[base].copy()
    w, x, y, z = data.xquat[base]
    lin_world = data.sensor("base_v").data.copy()        # the base origin's velocity, world
    ang_local = data.sensor("base_w").data.copy()        # a gyro at the base origin: base frame
    force = data.sensor("ft_force").data.copy() * SENSOR_SIGN
    torque = data.sensor("ft_torque").data.copy() * SENSOR_SIGN
    tau = data.qfrc_actuator[vadr].copy()
    return (*pos, x, y, z, w, *data.qpos[qadr], *lin_world, *ang_local, *data.qvel[vadr], *tau,
            *force, *torque)


SENSOR_SIGN = 1.0


def sensor_sign(urdf_path) -> float:
    """+1 if MuJoCo's force sensor reports the force ON the base (from its parent), −1 if the
    force BY the base: a leg hanging at rest on the rig must be pushed up with its weight."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf_from_urdf(urdf_path, floating=False, rigid=True))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mujoco.mj_rnePostConstraint(model, data)
    R = data.site_xmat[model.site("ft").id].reshape(3, 3)
    fz = (R @ data.sensor("ft_force").data)[2]
    weight = float(model.body_subtreemass[model.body("base").id] * 9.81)
    assert abs(abs(fz) - weight) < 1e-6 * weight, (fz, weight)
    return float(np.sign(fz))
