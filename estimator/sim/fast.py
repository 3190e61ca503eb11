"""Single-state right-hand side in plain floats (no per-call numpy overhead), for the integrators.

Same equations as estimator.dynamics (tests compare them to 1e-12) written for one state:
with φ_i = θ + Σ_{j≤i} q_j, e_i = (sin φ_i, −cos φ_i), ⊥e_i = (cos φ_i, sin φ_i),

    c_i = p_i + r_i e_i + s_i ⊥e_i,  J_i[:, x] = (1, 0), J_i[:, z] = (0, 1), J_i[:, θ or q_k] = ⊥(c_i − o_k),
    M = diag(m_b, m_b, I_b) + Σ_i m_i J_iᵀ J_i + I_i a_i a_iᵀ,
    C q̇ = Σ_i m_i J_iᵀ b_i,   b_i = −Σ_{j<i} l_j φ̇_j² e_j − φ̇_i² (r_i e_i + s_i ⊥e_i)   (c̈_i = J_i q̈ + b_i),
    G_k = g (m_b δ_{kz} + Σ_i m_i J_i[z, k]).
"""

from __future__ import annotations

import math

import numpy as np


class FastRHS:
    """ẏ(t, y) for one state of a Plant (see estimator.sim.model.Plant for the equation)."""

    def __init__(self, plant):
        self.plant = plant
        r = plant.robot
        self.N = plant.n_links
        self.l = [float(v) for v in r.lengths_m]
        self.r = [float(v) for v in r.com_m]
        self.rp = [float(v) for v in r.com_perp_m]
        self.m = [float(v) for v in r.masses_kg]
        self.I = [float(v) for v in r.inertias_kgm2]
        self.mb, self.Ib = float(r.base_mass_kg), float(r.base_inertia_kgm2)
        self.g = float(r.gravity_m_per_s2)
        self.rigid = plant.rigid
        self.K = [float(v) for v in plant.K_b]
        self.D = [float(v) for v in plant.D_b]
        self.pokes = [(p.link, p.alpha, p.t_on_s, p.t_off_s, p.ramp_s, *map(float, p.force_N))
                      for p in plant.pokes if p.t_off_s > p.t_on_s]
        c = plant.config.controller
        self.q0 = [float(v) for v in c.q0_rad]
        self.traj = c.amplitude_rad is not None
        if self.traj:
            a, f, ph = c.harmonics()
            self.A = a.tolist()
            self.w = (2 * math.pi * f).tolist()
            self.ph = ph.tolist()
        self.gc = c.gravity_compensation

    def kinematics(self, q):
        """Joint points p_1…p_{N+1}, unit vectors e_i, angles φ_i (floating layout q)."""
        x, z, th = q[0], q[1], q[2]
        phi, e, p = [], [], [(x, z)]
        a = th
        for i in range(self.N):
            a += q[3 + i]
            s, c = math.sin(a), math.cos(a)
            phi.append(a)
            e.append((s, -c))
            px, pz = p[-1]
            p.append((px + self.l[i] * s, pz - self.l[i] * c))
        return p, e, phi

    def point_jac(self, p, P, link):
        """Columns (2 × n) of the Jacobian of point P on ``link`` (1-based): list of (jx, jz)."""
        n = self.N + 3
        cols = [(0.0, 0.0)] * n
        cols[0], cols[1] = (1.0, 0.0), (0.0, 1.0)
        ox, oz = p[0]
        cols[2] = (-(P[1] - oz), P[0] - ox)
        for k in range(1, link + 1):
            ox, oz = p[k - 1]
            cols[2 + k] = (-(P[1] - oz), P[0] - ox)
        return cols

    def terms(self, q, dq):
        """M (n × n ndarray), C q̇ and G (lists), full floating coordinates."""
        N, n = self.N, self.N + 3
        p, e, phi = self.kinematics(q)
        M = [[0.0] * n for _ in range(n)]
        M[0][0] = M[1][1] = self.mb
        M[2][2] = self.Ib
        Cdq = [0.0] * n
        G = [0.0] * n
        G[1] = self.g * self.mb
        dphi, acc = [], dq[2]
        for i in range(N):
            acc += dq[3 + i]
            dphi.append(acc)
        bx = bz = 0.0      # Σ_{j<i} −l_j φ̇_j² e_j
        for i in range(N):
            ex, ez = e[i]
            w2 = dphi[i] * dphi[i]
            dx = self.r[i] * ex - self.rp[i] * ez       # r e + s ⊥e, ⊥e = (−e_z, e_x)
            dz = self.r[i] * ez + self.rp[i] * ex
            ci = (p[i][0] + dx, p[i][1] + dz)
            bix, biz = bx - w2 * dx, bz - w2 * dz
            bx -= self.l[i] * w2 * ex
            bz -= self.l[i] * w2 * ez
            cols = self.point_jac(p, ci, i + 1)
            active = [0, 1, 2] + list(range(3, 4 + i))
            mi = self.m[i]
            for a in active:
                ja = cols[a]
                Cdq[a] += mi * (ja[0] * bix + ja[1] * biz)
                G[a] += self.g * mi * ja[1]
                row = M[a]
                for b in active:
                    jb = cols[b]
                    row[b] += mi * (ja[0] * jb[0] + ja[1] * jb[1])
            # rotational: a_i has ones on θ and q_1…q_i
            rot = [2] + list(range(3, 4 + i))
            for a in rot:
                row = M[a]
                for b in rot:
                    row[b] += self.I[i]
        return M, Cdq, G, p, e

    def control(self, t, q, dq, G=None):
        nb = 3
        out = []
        for j in range(self.N):
            qd, dqd = self.q0[j], 0.0
            if self.traj:
                for a, w, ph in zip(self.A[j], self.w[j], self.ph[j]):
                    arg = w * t + ph
                    qd += a * math.sin(arg)
                    dqd += a * w * math.cos(arg)
            tau = self.plant.kp * (qd - q[nb + j]) + self.plant.kd * (dqd - dq[nb + j])
            if self.gc and G is not None:
                tau += G[nb + j]
            out.append(tau)
        return out

    def __call__(self, t, y, tau_hold=None):
        plant = self.plant
        self.plant.nfev += 1
        N = self.N
        yl = y.tolist()
        if self.rigid:
            q = [0.0, 0.0, 0.0] + yl[:N]
            dq = [0.0, 0.0, 0.0] + yl[N:2 * N]
        else:
            n = N + 3
            q, dq = yl[:n], yl[n:2 * n]
        M, Cdq, G, p, e = self.terms(q, dq)
        gen = [-Cdq[k] - G[k] for k in range(N + 3)]
        tau = self.control(t, q, dq, G) if tau_hold is None else list(np.ravel(tau_hold))
        for j in range(N):
            gen[3 + j] += tau[j]
        if not self.rigid:
            for k in range(3):
                gen[k] += -self.K[k] * q[k] - self.D[k] * dq[k]
        for link, alpha, t_on, t_off, ramp, F0x, F0z in self.pokes:
            if ramp > 0:
                s = max(0.0, min(1.0, (t - t_on) / ramp, 1.0 - (t - t_off) / ramp))
            else:
                s = 1.0 if t_on <= t < t_off else 0.0
            if s == 0.0:
                continue
            Fx, Fz = s * F0x, s * F0z
            pc = p[link - 1]
            P = (pc[0] + alpha * self.l[link - 1] * e[link - 1][0],
                 pc[1] + alpha * self.l[link - 1] * e[link - 1][1])
            for k, (jx, jz) in enumerate(self.point_jac(p, P, link)):
                gen[k] += jx * Fx + jz * Fz
        extra = []
        if plant.has_ground:
            qa, dqa = np.asarray(q)[None], np.asarray(dq)[None]
            s_arr = np.array([y[-1]])
            F, ds = plant.ground_force(qa if not self.rigid else qa, dqa, s_arr)
            cols = self.point_jac(p, p[N], N)
            for k, (jx, jz) in enumerate(cols):
                gen[k] += jx * F[0, 0] + jz * F[0, 1]
            extra = [float(ds[0])]
        M = np.array(M)
        if self.rigid:
            ddq = np.linalg.solve(M[3:, 3:], np.asarray(gen[3:]))
            return np.concatenate([y[N:2 * N], ddq])
        ddq = np.linalg.solve(M, np.asarray(gen))
        n = N + 3
        return np.concatenate([y[n:2 * n], ddq, extra])
