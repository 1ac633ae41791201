#!/usr/bin/env python
"""Toy stereo EKF-SLAM looking up at ceiling lamps: diagnose drift of the baseline B.

State: [X, Y, theta, B, s, landmark params ...]
  - B : stereo baseline (true 0.1107, nominal 0.1105 +- 0.0003)
  - s : odometry scale, reported translation = s * true translation (true 0.999, prior 1 +- 0.02)
Landmark parametrisations ('param'):
  - 'xyz'      : world (Lx, Ly, Lz)
  - 'invdepth' : world (Lx, Ly, rho = 1/(Lz - mz))   (depth is pose-independent here)
  - 'bunits'   : scale-free: poses/lamps relative to start in units of B, depth/B; state s' = s*B
  - 'anchored' : (Xa, Ya, tha, ua, va, da) = anchor pose copy + pixel/disparity of first sighting;
                 the world point depends on the *current* B through Z = f B / da.
Measurement per lamp: (uL, uR, vL, vR), independent N(0, sigma_px) noise.

Usage examples (see main()):
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5                      # exp 1, baseline
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --sigma_px 0         # no pixel noise
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --mx 0.5             # bigger lever arm
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --iters 4            # iterated EKF
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --param invdepth     # or anchored
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --no_s               # s fixed (not estimated)
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --route straight     # no turns
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --no_stops
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --oracle lm          # H evaluated at true landmarks (lm|all|Bcol)
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --retract 1          # metres, correction in B units (vslam_ekf's fix)
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --retract 1 --retract_active 2  # ... on pose, B, s alone
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --retract 2          # ... the mean alone (no fix)
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --retract 1 --retract_every 20  # deferred (no fix)
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-5 --retract 1 --odo_noise 0.002 [--col true|prev [--col_gauge 1]]
                                                   # odometry noise; the odometry scale's column from the report,
                                                   # the true motion or the previous frame, the gauge kept or not
  .venv/bin/python scripts/scale_drift_toy.py run --seeds 0-4 --retract 1 --retract_active 2 --follow 1 --odo_noise 0.002 --mx 0.5
                                                   # the lamps' linearisation points follow their estimates as
                                                   # vslam_ekf's follow_points does (--follow 2: the heading's
                                                   # shear alone, with --retract_active 1)
"""
import argparse
import json
import sys
import time
from dataclasses import dataclass, asdict, field

import numpy as np

# ----------------------------------------------------------------------------- constants
F_PX, CX, CY, W_IMG, H_IMG = 458.0, 376.0, 240.0, 752, 480
DT = 0.05
B_TRUE, B_NOM, B_SIG = 0.1107, 0.1105, 0.0003
S_TRUE, S_NOM, S_SIG = 0.999, 1.0, 0.02
IX, IY, ITH, IB, IS = 0, 1, 2, 3, 4
NG = 5  # number of global state entries


@dataclass
class Cfg:
    seed: int = 0
    sigma_px: float = 0.3
    mx: float = 0.1
    my: float = 0.0
    mz: float = 1.7
    route: str = 'full'        # 'full' (aisles + 180 deg turns) | 'straight'
    stops: bool = True
    est_s: bool = True         # estimate s (else s fixed at its true value, not in the filter)
    iters: int = 1             # >1: iterated EKF
    param: str = 'xyz'         # 'xyz' | 'invdepth' | 'anchored'
    oracle: str = ''           # '' | 'lm' (H at true landmarks) | 'all' (H at full true state) | 'Bcol'
    init_mode: str = 'meas'    # 'meas' | 'true' (oracle: landmark mean initialised at truth) | 'unbiased'
    b_true: float = B_TRUE
    s_true: float = S_TRUE
    q_pos: float = 0.002
    odo_noise: float = 0.0     # reported translation noise per frame, metres (white; the filter's
                               # q_pos should cover it)
    col_gauge: int = 0         # 1: the column's difference from the report put in B's column
    col: str = 'rep'           # odometry scale's column from: 'rep' (the frame's report), 'true'
                               # (oracle: the true motion), 'prev' (the previous frame's report),
                               # 'post' (re-linearised at the posterior displacement after the update)
    q_th: float = 0.0005
    sigma_meas_filter: float = -1.0  # R used in the filter (default: = sigma_px, floor 1e-3)
    retract_every: int = 1     # apply the retraction every this many frames, from the state
                               # when it was last applied (the transforms compose)
    retract_active: int = 0    # 1: the transform only on the globals and the lamps observed;
                               # 2: on the globals (pose, B, s) alone
    retract: int = 0           # 1 (xyz only): metric state, each update's correction applied in
                               # baseline units about the start pose and mapped back; 2: the
                               # mean only (the covariance left as the metric update gives it)
    turn_omega: float = 0.45
    turn_radius: float = 2.5
    spacing: float = 4.0
    follow: int = 0            # 1: each observed lamp's linearisation point follows its estimate
                               # with the covariance sheared as vslam_ekf's follow_points does
                               # (heading column J d, baseline column (L - C)/B re-taken at the
                               # new point and baseline, C the placing camera); 2: the heading's
                               # shear alone (the baseline's share left to the retraction)


# ----------------------------------------------------------------------------- world + route
def make_route(cfg):
    """Return per-frame true increments in the vehicle frame (dx, dy, dth) and a phase label
    0=straight, 1=turn, 2=stop."""
    if cfg.route not in ('full', 'straight'):
        raise ValueError(cfg.route)
    segs = []
    for a in range(6):
        # straight aisle of 40 m at 1 m/s, with a stop in the middle of aisles 1,2,4,5
        if cfg.stops and a in (1, 2, 4, 5):
            segs += [('S', 20.0), ('P', 3.0 + (a % 3)), ('S', 20.0)]
        else:
            segs += [('S', 40.0)]
        if a < 5:
            # 'full': a semicircle to the next aisle; 'straight': the same length straight on
            # (about the same number of frames, no turn)
            if cfg.route == 'full':
                segs += [('T', +1 if a % 2 == 0 else -1)]
            else:
                segs += [('S', np.pi * cfg.turn_radius)]
    inc, ph = [], []
    for kind, arg in segs:
        if kind == 'S':
            n = int(round(arg / (1.0 * DT)))
            inc += [(1.0 * DT, 0.0, 0.0)] * n
            ph += [0] * n
        elif kind == 'P':
            n = int(round(arg / DT))
            inc += [(0.0, 0.0, 0.0)] * n
            ph += [2] * n
        else:  # semicircle, sign arg = +1 ccw, -1 cw
            dth = cfg.turn_omega * DT
            n = int(round(np.pi / dth))
            r = cfg.turn_radius
            inc += [(r * np.sin(dth), arg * r * (1 - np.cos(dth)), arg * dth)] * n
            ph += [1] * n
    return np.array(inc), np.array(ph)


def compose(pose, inc):
    X, Y, th = pose
    c, s = np.cos(th), np.sin(th)
    return np.array([X + c * inc[0] - s * inc[1], Y + s * inc[0] + c * inc[1], th + inc[2]])


def make_world(cfg, rng, inc):
    poses = [np.array([20.0, 8.0, 0.0])]
    for d in inc:
        poses.append(compose(poses[-1], d))
    poses = np.array(poses)
    lo = poses[:, :2].min(0) - 12
    hi = poses[:, :2].max(0) + 12
    gx = np.arange(lo[0], hi[0], cfg.spacing)
    gy = np.arange(lo[1], hi[1], cfg.spacing)
    GX, GY = np.meshgrid(gx, gy)
    L = np.stack([GX.ravel(), GY.ravel()], 1)
    L = L + rng.uniform(-0.6, 0.6, L.shape)
    Lz = rng.uniform(6.5, 8.5, len(L))
    return poses, np.column_stack([L, Lz])


# ----------------------------------------------------------------------------- models
def project_world(glob, Lw, m):
    """glob: (k,4) [X,Y,th,B]; Lw (k,3) world points -> (k,4) [uL,uR,vL,vR]."""
    X, Y, th, B = glob.T
    c, s = np.cos(th), np.sin(th)
    dx, dy = Lw[:, 0] - X, Lw[:, 1] - Y
    px = c * dx + s * dy - m[0]
    py = -s * dx + c * dy - m[1]
    Z = Lw[:, 2] - m[2]
    uL = F_PX * (px + B / 2) / Z + CX
    uR = F_PX * (px - B / 2) / Z + CX
    v = F_PX * py / Z + CY
    return np.column_stack([uL, uR, v, v])


def lm_to_world(glob, lm, param, m):
    if param == 'xyz':
        return lm
    if param == 'invdepth':
        return np.column_stack([lm[:, 0], lm[:, 1], m[2] + 1.0 / lm[:, 2]])
    if param == 'bunits':   # (relative to the start position)
        B = glob[:, 3:4]
        return np.column_stack([B[:, 0] * lm[:, 0], B[:, 0] * lm[:, 1], m[2] + B[:, 0] * lm[:, 2]])
    if param == 'anchored':
        B = glob[:, 3]
        Xa, Ya, tha, ua, va, da = lm.T
        Z = F_PX * B / da
        pax = (ua - CX) * Z / F_PX + m[0]
        pay = (va - CY) * Z / F_PX + m[1]
        c, s = np.cos(tha), np.sin(tha)
        return np.column_stack([Xa + c * pax - s * pay, Ya + s * pax + c * pay, Z + m[2]])
    raise ValueError(param)


def h_lm(glob, lm, param, m):
    if param == 'bunits':
        # all lengths in units of the baseline: pose' = (pose - start)/B, lamp' = (Lx', Ly', Z/B)
        X, Y, th, B = glob.T
        c, s = np.cos(th), np.sin(th)
        dx, dy = lm[:, 0] - X, lm[:, 1] - Y
        px = c * dx + s * dy - m[0] / B
        py = -s * dx + c * dy - m[1] / B
        Z = lm[:, 2]
        v = F_PX * py / Z + CY
        return np.column_stack([F_PX * (px + 0.5) / Z + CX, F_PX * (px - 0.5) / Z + CX, v, v])
    return project_world(glob, lm_to_world(glob, lm, param, m), m)


def init_lm(glob, z, param, m):
    """Landmark params from one stereo observation z=(uL,uR,vL,vR) at pose/B glob."""
    X, Y, th, B = glob.T
    uL, uR, vL, vR = z.T
    d = uL - uR
    um, vm = 0.5 * (uL + uR), 0.5 * (vL + vR)
    if param == 'anchored':
        return np.column_stack([X, Y, th, um, vm, d])
    if param == 'bunits':
        Z = F_PX / d
        px = (um - CX) * Z / F_PX + m[0] / B
        py = (vm - CY) * Z / F_PX + m[1] / B
        c, s = np.cos(th), np.sin(th)
        return np.column_stack([X + c * px - s * py, Y + s * px + c * py, Z])
    Z = F_PX * B / d
    px = (um - CX) * Z / F_PX + m[0]
    py = (vm - CY) * Z / F_PX + m[1]
    c, s = np.cos(th), np.sin(th)
    Lx, Ly = X + c * px - s * py, Y + s * px + c * py
    if param == 'xyz':
        return np.column_stack([Lx, Ly, Z + m[2]])
    return np.column_stack([Lx, Ly, 1.0 / Z])


def num_jac(fun, args, which, eps=1e-6):
    """Central-difference Jacobian of vectorised fun(*args) -> (k,p) w.r.t. columns of args[which].
    Returns (k, p, q)."""
    a = [np.array(x, dtype=float) for x in args]
    base = a[which]
    q = base.shape[1]
    cols = []
    for j in range(q):
        e = eps * np.maximum(1.0, np.abs(base[:, j]))
        ap = list(a); am = list(a)
        bp = base.copy(); bp[:, j] += e
        bm = base.copy(); bm[:, j] -= e
        ap[which] = bp; am[which] = bm
        cols.append((fun(*ap) - fun(*am)) / (2 * e[:, None]))
    return np.stack(cols, axis=2)


LM_DIM = {'xyz': 3, 'invdepth': 3, 'anchored': 6, 'bunits': 3}


# ----------------------------------------------------------------------------- EKF
def run(cfg: Cfg, record_every=20):
    rng = np.random.default_rng(cfg.seed)
    inc, phase = make_route(cfg)
    poses, lamps = make_world(cfg, rng, inc)
    m = np.array([cfg.mx, cfg.my, cfg.mz])
    nL = len(lamps)
    k = LM_DIM[cfg.param]
    nmax = NG + k * nL
    x = np.zeros(nmax)
    P = np.zeros((nmax, nmax))
    x[:3] = poses[0]
    x[IB], x[IS] = B_NOM, S_NOM
    P[ITH, ITH] = 1e-12; P[IX, IX] = P[IY, IY] = 1e-12
    P[IB, IB] = B_SIG ** 2
    P[IS, IS] = S_SIG ** 2 if cfg.est_s else 0.0
    if not cfg.est_s:
        x[IS] = cfg.s_true
    BU = cfg.param == 'bunits'
    if BU:
        # filter frame: origin at the (exactly known) start position, lengths in units of B;
        # the odometry-scale state becomes s' = s*B (reported/s' = true translation in B units)
        x[:2] = 0.0
        Jp = np.array([[1.0, 0.0], [x[IS], B_NOM]])
        P[np.ix_([IB, IS], [IB, IS])] = Jp @ P[np.ix_([IB, IS], [IB, IS])] @ Jp.T
        x[IS] = x[IS] * B_NOM
    n = NG
    slot = -np.ones(nL, int)      # state offset of lamp i (or -1)
    first = np.zeros((nL, 3))     # follow: each lamp's linearisation point
    cam_at = np.zeros((nL, 3))    # follow: the camera it was placed from
    b_first = np.zeros(nL)        # follow: the baseline its column was last taken at
    sig = cfg.sigma_px
    sigR = cfg.sigma_meas_filter if cfg.sigma_meas_filter > 0 else max(sig, 1e-3)
    Rl = sigR ** 2 * np.eye(4)
    gidx = np.array([IX, IY, ITH, IB])
    # true landmark params (for oracles); only meaningful for xyz
    rec = {'t': [], 'B': [], 'sB': [], 's': [], 'ss': [], 'eX': [], 'nvis': [], 'nlm': []}
    dB = np.zeros(len(inc) + 1)     # B change in each frame's update
    newf = np.zeros(len(inc) + 1, bool)
    q = np.array([cfg.q_pos, cfg.q_pos, cfg.q_th]) ** 2
    if cfg.param == 'bunits':
        q[:2] /= B_NOM ** 2
    rec_every = record_every

    def measure_all(pose_true):
        glob_t = np.tile(np.r_[pose_true, cfg.b_true], (nL, 1))
        zt = project_world(glob_t, lamps, m)
        vis = ((zt[:, 0] >= 0) & (zt[:, 0] < W_IMG) & (zt[:, 1] >= 0) & (zt[:, 1] < W_IMG) &
               (zt[:, 2] >= 0) & (zt[:, 2] < H_IMG))
        ids = np.nonzero(vis)[0]
        z = zt[ids] + sig * rng.standard_normal((len(ids), 4))
        return ids, z

    def lin(xc, ids):
        """Predicted measurement and Jacobian for lamps ids at state xc.
        Returns hpred (4m,), Hsub (4m, len(cols)), cols."""
        mm = len(ids)
        offs = slot[ids]
        lm = xc[offs[:, None] + np.arange(k)]
        glob = np.tile(xc[gidx], (mm, 1))
        hp = h_lm(glob, lm, cfg.param, m).ravel()
        # linearisation point for H (possibly oracle)
        glob_H, lm_H = glob, lm
        if cfg.oracle in ('lm', 'all', 'Bcol'):
            assert cfg.param == 'xyz'
            lm_H = lamps[ids]
            if cfg.oracle == 'all':
                glob_H = np.tile(np.r_[poses_cur[0], cfg.b_true], (mm, 1))
        fun = lambda g, l: h_lm(g, l, cfg.param, m)
        Jg = num_jac(fun, (glob_H, lm_H), 0)   # (mm,4,4)
        Jl = num_jac(fun, (glob_H, lm_H), 1)   # (mm,4,k)
        if cfg.oracle == 'Bcol':
            # only the B column from the oracle; everything else at the estimate
            Jg_est = num_jac(fun, (glob, lm), 0)
            Jl = num_jac(fun, (glob, lm), 1)
            Jg_est[:, :, 3] = Jg[:, :, 3]
            Jg = Jg_est
        cols = np.r_[gidx, (offs[:, None] + np.arange(k)).ravel()]
        H = np.zeros((4 * mm, len(cols)))
        for j in range(mm):
            H[4 * j:4 * j + 4, :4] = Jg[j]
            H[4 * j:4 * j + 4, 4 + k * j:4 + k * (j + 1)] = Jl[j]
        return hp, H, cols

    poses_cur = [poses[0]]
    odo_rng = np.random.default_rng(10_000 + cfg.seed)
    prev_rep = [np.zeros(2)]
    pose_before = np.zeros(3)
    used_col = np.zeros(2)
    Dacc = np.ones(nmax)
    aacc = np.zeros(nmax)
    origin = np.zeros(nmax)          # per metric entry: the point lengths are measured from
    metric = np.zeros(nmax, bool)
    origin[IX], origin[IY] = poses[0][:2]
    metric[[IX, IY]] = True
    for j in range(nL):
        o = NG + 3 * j
        origin[o:o + 3] = [poses[0][0], poses[0][1], m[2]]
        metric[o:o + 3] = True

    def retract_in_baseline_units(x0, x, P, n):
        """Re-apply the linear correction x - x0 in coordinates (c - o)/B, s*B, map back the
        mean; return the covariance's transform M = T_back(new) T_fwd(old) as (D, a):
        M = diag(D) + a e_B^T."""
        B0, B1 = x0[IB], x[IB]
        dB = B1 - B0
        mk = metric[:n]
        o = origin[:n]
        d = x[:n] - x0[:n]
        xb0 = (x0[:n] - o) / B0                       # old point in baseline units
        xbn = xb0 + d / B0 - xb0 * dB / B0            # the linear correction in those units
        D = np.ones(n)
        a = np.zeros(n)
        new = x[:n].copy()
        new[mk] = o[mk] + B1 * xbn[mk]
        sp = x0[IS] * B0 + B0 * d[IS] + x0[IS] * dB     # s' = s B, corrected linearly
        new[IS] = sp / B1
        D[mk] = B1 / B0
        a[mk] = xbn[mk] - B1 * xb0[mk] / B0
        # s = s'/B: ds/ds = B0/B1, ds/dB = s0/B1 - s'/B1^2
        D[IS] = B0 / B1
        a[IS] = x0[IS] / B1 - sp / B1 ** 2
        x[:n] = new
        return D, a

    def apply_m(P, n, D, a):
        M = np.diag(D) + np.outer(a, np.eye(n)[IB])
        if cfg.retract == 1:
            P[:n, :n] = M @ P[:n, :n] @ M.T

    def s_est(x, P):
        if cfg.param != 'bunits':
            return x[IS], np.sqrt(max(P[IS, IS], 0))
        g = np.array([-x[IS] / x[IB] ** 2, 1 / x[IB]])
        return x[IS] / x[IB], np.sqrt(g @ P[np.ix_([IB, IS], [IB, IS])] @ g)

    def pos_est(x):
        return x[:2] * x[IB] + poses[0][:2] if cfg.param == 'bunits' else x[:2]
    for t in range(len(inc) + 1):
        if t > 0:
            # ------------------------------------------------ prediction with reported odometry
            d = inc[t - 1]
            rep = np.array([cfg.s_true * d[0], cfg.s_true * d[1]])
            rep_clean = rep.copy()
            if cfg.odo_noise > 0:
                rep = rep + cfg.odo_noise * odo_rng.standard_normal(2)
            sc = x[IS]
            X, Y, th = x[:3]
            c, s_ = np.cos(th), np.sin(th)
            tx, ty = rep / sc
            pose_before[:] = x[:3]
            x[:3] = [X + c * tx - s_ * ty, Y + s_ * tx + c * ty, th + d[2]]
            J = np.zeros((3, NG))
            J[:, :3] = np.eye(3)
            J[0, 2] = -s_ * tx - c * ty
            J[1, 2] = c * tx - s_ * ty
            colrep = {'rep': rep, 'true': rep_clean, 'prev': prev_rep[0], 'post': rep}[cfg.col]
            cx_, cy_ = colrep / sc
            J[0, IS] = -(c * cx_ - s_ * cy_) / sc
            J[1, IS] = -(s_ * cx_ + c * cy_) / sc
            if cfg.col_gauge:
                # keep the metric scale's direction (X, B, -s) a null direction of the
                # prediction: the column's difference from the report goes to B's column
                J[0, IB] = (c * (tx - cx_) - s_ * (ty - cy_)) / x[IB]
                J[1, IB] = (s_ * (tx - cx_) + c * (ty - cy_)) / x[IB]
            used_col[:] = J[:2, IS]
            prev_rep[0] = rep
            A = J @ P[:NG, :n]                  # new pose rows
            Ppp = A[:, :NG] @ J.T
            P[:3, :n] = A
            P[:n, :3] = A.T
            P[:3, :3] = Ppp
            P[[0, 1, 2], [0, 1, 2]] += q
        poses_cur[0] = poses[t]
        ids, z = measure_all(poses[t])
        known = slot[ids] >= 0
        B_before = x[IB]
        # ------------------------------------------------ update with known lamps
        if known.any():
            kid, zk = ids[known], z[known].ravel()
            x0 = x[:n].copy()
            xi = x0.copy()
            for it in range(cfg.iters):
                hp, H, cols = lin(xi, kid)
                nu = zk - hp - H @ (x0[cols] - xi[cols])
                PHt = P[:n, cols] @ H.T
                S = H @ PHt[cols] + np.kron(np.eye(len(kid)), Rl)
                K = np.linalg.solve(S, PHt.T).T
                xi = x0 + K @ nu
            x[:n] = xi
            KP = K @ PHt.T
            # Joseph form with the exact gain: (I-KH)P(I-KH)' + KRK' = P - KHP - PH'K' + KSK'
            P[:n, :n] += -KP - KP.T + K @ S @ K.T
            P[:n, :n] = 0.5 * (P[:n, :n] + P[:n, :n].T)
            if cfg.col == 'post' and t > 0:
                # the prediction's odometry-scale column re-linearised at the posterior
                # displacement: -R^T-free world displacement / s (the noise taken out)
                post_col = -(x[:2] - pose_before[:2]) / x[IS]
                shear = post_col - used_col
                Tm = np.eye(n)
                Tm[0, IS] += shear[0]
                Tm[1, IS] += shear[1]
                P[:n, :n] = Tm @ P[:n, :n] @ Tm.T
            if cfg.retract:
                D, a = retract_in_baseline_units(x0, x, P, n)
                if cfg.retract_active:
                    # only the states this frame observed (and the globals) take the transform
                    act = np.zeros(n, bool)
                    act[:NG] = True
                    if cfg.retract_active == 1:
                        act[(slot[kid][:, None] + np.arange(k)).ravel()] = True
                    D[~act] = 1.0
                    a[~act] = 0.0
                # compose with the transforms not yet applied: M2 M1 = D2 D1 + (D2 a1 + a2) e_B^T
                Dacc[:n] = D * Dacc[:n]
                aacc[:n] = D * aacc[:n] + a
                if t % cfg.retract_every == 0:
                    apply_m(P, n, Dacc[:n], aacc[:n])
                    Dacc[:] = 1.0
                    aacc[:] = 0.0
            if cfg.follow:
                B1 = x[IB]
                for lid in kid:
                    o = slot[lid]
                    L = x[o:o + 3].copy()
                    dd = L - first[lid]
                    # T = I + u e_theta^T + w e_B^T on the lamp's rows: P <- T P T^T
                    u = np.array([-dd[1], dd[0], 0.0])
                    w = np.zeros(3)
                    if cfg.follow == 1:
                        w = (L - cam_at[lid]) / B1 - (first[lid] - cam_at[lid]) / b_first[lid]
                    P[o:o + 3, :n] += np.outer(u, P[ITH, :n]) + np.outer(w, P[IB, :n])
                    P[:n, o:o + 3] += np.outer(P[:n, ITH], u) + np.outer(P[:n, IB], w)
                    first[lid] = L
                    b_first[lid] = B1
            if not cfg.est_s:
                P[IS, :n] = 0; P[:n, IS] = 0
        dB[t] = x[IB] - B_before
        # ------------------------------------------------ initialise new lamps (after update)
        new = ~known
        if new.any():
            newf[t] = True
            nid, zn = ids[new], z[new]
            mm = len(nid)
            glob = np.tile(x[gidx], (mm, 1))
            lm = init_lm(glob, zn, cfg.param, m)
            fun = lambda g, zz: init_lm(g, zz, cfg.param, m)
            Jg = num_jac(fun, (glob, zn), 0)   # (mm,k,4)
            Jz = num_jac(fun, (glob, zn), 1)   # (mm,k,4)
            if cfg.init_mode == 'true':
                assert cfg.param == 'xyz'
                lm = lamps[nid].copy()
            elif cfg.init_mode == 'unbiased':
                assert cfg.param == 'xyz'
                # second-order correction of E[1/d]: Z = fB/d * (1 - var_d/d^2)
                dd = zn[:, 0] - zn[:, 1]
                corr = 1.0 - 2 * sigR ** 2 / dd ** 2
                glob2 = glob.copy(); glob2[:, 3] *= corr
                lm = init_lm(glob2, zn, cfg.param, m)
            Ag = Jg.reshape(mm * k, 4)
            newcols = n + np.arange(mm * k)
            Pno = Ag @ P[gidx, :n]
            Pnn = Ag @ P[np.ix_(gidx, gidx)] @ Ag.T
            for j in range(mm):
                Pnn[k * j:k * j + k, k * j:k * j + k] += Jz[j] @ Rl @ Jz[j].T
            x[newcols] = lm.ravel()
            P[n:n + mm * k, :n] = Pno
            P[:n, n:n + mm * k] = Pno.T
            P[n:n + mm * k, n:n + mm * k] = Pnn
            slot[nid] = n + k * np.arange(mm)
            first[nid] = lm[:, :3]
            cth, sth = np.cos(x[ITH]), np.sin(x[ITH])
            cam_at[nid] = [x[IX] + cth * m[0] - sth * m[1], x[IY] + sth * m[0] + cth * m[1], m[2]]
            b_first[nid] = x[IB]
            n += mm * k
        if t % rec_every == 0 or t == len(inc):
            rec['t'].append(t); rec['B'].append(x[IB]); rec['sB'].append(np.sqrt(P[IB, IB]))
            rec['s'].append(s_est(x, P)[0]); rec['ss'].append(s_est(x, P)[1])
            rec['eX'].append(float(np.hypot(*(pos_est(x) - poses[t][:2]))))
            rec['nvis'].append(len(ids)); rec['nlm'].append(int((slot >= 0).sum()))
    # landmark height errors (xyz: direct; others: convert)
    seen = np.nonzero(slot >= 0)[0]
    lmv = x[slot[seen][:, None] + np.arange(k)]
    Lw = lm_to_world(np.tile(x[gidx], (len(seen), 1)), lmv, cfg.param, m)
    zerr = (Lw[:, 2] - m[2]) / (lamps[seen, 2] - m[2]) - 1.0
    ph = np.r_[phase, phase[-1]]
    out = dict(cfg=asdict(cfg), rec=rec,
               B_end=x[IB], sB_end=np.sqrt(P[IB, IB]), s_end=s_est(x, P)[0], ss_end=s_est(x, P)[1],
               drift_sig=(x[IB] - B_NOM) / B_SIG, err_sig=(x[IB] - cfg.b_true) / B_SIG,
               err_post=(x[IB] - cfg.b_true) / np.sqrt(P[IB, IB]),
               s_err_rel=(s_est(x, P)[0] - cfg.s_true) / cfg.s_true,
               Bs_err_rel=(x[IB] * s_est(x, P)[0]) / (cfg.b_true * cfg.s_true) - 1,
               depth_scale_err=float(np.mean(zerr)),
               dB_newframes=float(dB[newf].sum() / B_SIG), dB_oldframes=float(dB[~newf].sum() / B_SIG),
               dB_straight=float(dB[~newf & (ph == 0)].sum() / B_SIG),
               dB_turn=float(dB[~newf & (ph == 1)].sum() / B_SIG),
               dB_stop=float(dB[~newf & (ph == 2)].sum() / B_SIG),
               nframes=len(inc) + 1, nlm=int(len(seen)),
               pos_err_end=float(np.hypot(*(pos_est(x) - poses[-1][:2]))))
    return out


# ----------------------------------------------------------------------------- driver
def parse_seeds(s):
    if '-' in s:
        a, b = s.split('-')
        return list(range(int(a), int(b)))
    return [int(v) for v in s.split(',')]


def _run1(cfg):
    t0 = time.time()
    r = run(cfg)
    r['wall'] = time.time() - t0
    return r


def summarize(res, label=''):
    keys = ['drift_sig', 'err_sig', 'err_post', 'sB_end', 's_err_rel', 'Bs_err_rel', 'depth_scale_err',
            'dB_newframes', 'dB_oldframes', 'dB_straight', 'dB_turn', 'dB_stop']
    lines = [f'== {label}  (n={len(res)} seeds, frames={res[0]["nframes"]}, lamps={np.mean([r["nlm"] for r in res]):.0f}, '
             f'wall/run={np.mean([r["wall"] for r in res]):.1f}s)']
    for kk in keys:
        v = np.array([r[kk] for r in res])
        lines.append(f'  {kk:16s} mean {v.mean():+.4g}  sem {v.std(ddof=1) / np.sqrt(len(v)) if len(v) > 1 else 0:.3g}   '
                     f'[{", ".join(f"{a:+.3g}" for a in v)}]')
    return '\n'.join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('cmd', choices=['run'])
    ap.add_argument('--seeds', default='0-6')
    ap.add_argument('--label', default='')
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--out', default='')
    for f_ in Cfg.__dataclass_fields__.values():
        if f_.name == 'seed':
            continue
        if f_.type in (bool, 'bool'):
            continue
        ap.add_argument('--' + f_.name, type=type(f_.default), default=f_.default)
    ap.add_argument('--no_stops', action='store_true')
    ap.add_argument('--no_s', action='store_true')
    a = ap.parse_args()
    kw = {k_: getattr(a, k_) for k_ in Cfg.__dataclass_fields__ if hasattr(a, k_) and k_ != 'seed'}
    kw['stops'] = not a.no_stops
    kw['est_s'] = not a.no_s
    cfgs = [Cfg(seed=sd, **kw) for sd in parse_seeds(a.seeds)]
    if a.jobs > 1:
        from multiprocessing import Pool
        with Pool(a.jobs) as pool:
            res = pool.map(_run1, cfgs)
    else:
        res = [_run1(c) for c in cfgs]
    label = a.label or ' '.join(sys.argv[2:])
    print(summarize(res, label))
    if a.out:
        with open(a.out, 'w') as fh:
            json.dump(res, fh, default=float)


if __name__ == '__main__':
    main()
