"""Test helpers: random URDF trees (any joint types, unaligned axes, fixed links) for the spatial
model's checks against pinocchio."""

from __future__ import annotations

import numpy as np


def _inertial(rng, mass):
    A = rng.normal(size=(3, 3))
    I = A @ A.T * 1e-3 + np.eye(3) * 1e-3
    c = rng.normal(size=3) * 0.05
    return (f'<inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="0.1 -0.2 0.3"/><mass value="{mass}"/>'
            f'<inertia ixx="{I[0,0]}" ixy="{I[0,1]}" ixz="{I[0,2]}" iyy="{I[1,1]}" iyz="{I[1,2]}" '
            f'izz="{I[2,2]}"/></inertial>')


def random_tree_urdf(seed: int = 0, n: int = 5) -> str:
    """A URDF with ``n`` movable joints on a tree (each joint's parent drawn among the earlier
    links), revolute / continuous / prismatic with random axes, and a fixed child link."""
    rng = np.random.default_rng(seed)
    links = [f'<link name="l0">{_inertial(rng, 1.0)}<collision><geometry><box size="0.1 0.1 0.1"/>'
             f'</geometry></collision></link>']
    joints = []
    kinds = ["revolute", "continuous", "prismatic"]
    for i in range(1, n + 1):
        parent = int(rng.integers(0, i))
        kind = kinds[i % 3]
        ax = rng.normal(size=3)
        if i % 2:
            ax = np.eye(3)[i % 3]
        ax /= np.linalg.norm(ax)
        xyz = rng.normal(size=3) * 0.1
        rpy = rng.normal(size=3)
        links.append(f'<link name="l{i}">{_inertial(rng, 0.2 + rng.random())}</link>')
        lim = '<limit lower="-3" upper="3" effort="10" velocity="10"/>' if kind != "continuous" else ""
        joints.append(f'<joint name="j{i}" type="{kind}"><parent link="l{parent}"/><child link="l{i}"/>'
                      f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
                      f'<axis xyz="{ax[0]} {ax[1]} {ax[2]}"/>{lim}</joint>')
    links.append(f'<link name="tip">{_inertial(rng, 0.1)}</link>')
    joints.append(f'<joint name="tipfix" type="fixed"><parent link="l{n}"/><child link="tip"/>'
                  f'<origin xyz="0.1 0 0" rpy="0 0.5 0"/></joint>')
    return '<?xml version="1.0"?><robot name="rand">' + "".join(links + joints) + "</robot>"


def random_states(rng, T: int, n_joints: int, scale: float = 1.0):
    """q (T, 7 + n), v, τ (T, 6 + n) with unit quaternions."""
    q = np.c_[rng.normal(size=(T, 3)), rng.normal(size=(T, 4)), rng.normal(size=(T, n_joints))]
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    v = rng.normal(size=(T, 6 + n_joints)) * scale
    tau = rng.normal(size=(T, 6 + n_joints))
    return q, v, tau
