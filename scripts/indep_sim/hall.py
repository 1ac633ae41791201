#!/usr/bin/env python3
"""Independent hall simulator for the stereonav stack.

Written only from /work/shared/vehicle-interfaces.md (sections 1, 1.1, 1.2, 2, 3, 4, 5)
and /work/shared/board-icd.md (section 3, plus the meaning of `r` and the raster order
of section 2 step 7).  See README.md in this directory for every interpretation made.

Usage:
    python hall.py --out DIR [--seed N] [--memory-tau S] [--lens radtan|none] [--aisles K] ...

Writes DIR/hall.mcap, DIR/rig.toml, DIR/truth.json.
"""

import argparse
import json
import math
import os
import struct
import sys
import zlib

import numpy as np
from mcap.writer import CompressionType, Writer

# --------------------------------------------------------------------------------------
# constants of the contract
# --------------------------------------------------------------------------------------
SYNC = bytes([0x5A, 0xA5, 0x3C, 0xC3])  # board-icd 3
WIDTH, HEIGHT = 752, 480                 # board registers default / brief
MAX_FEATURES = 512                       # board default register (board-icd 1)
ODOM_DT_US = 10_000                      # 100 Hz
FRAME_DT_US = 50_000                     # 20 Hz
FINE_DT_US = 1_000                       # internal simulation step (1 ms)


# --------------------------------------------------------------------------------------
# small geometry helpers
# --------------------------------------------------------------------------------------
def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def rodrigues(w):
    w = np.asarray(w, dtype=float)
    th = np.linalg.norm(w)
    if th < 1e-15:
        return np.eye(3)
    k = w / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


# --------------------------------------------------------------------------------------
# lens model (vehicle-interfaces 1.1): OpenCV plumb_bob forward model
# --------------------------------------------------------------------------------------
class Lens:
    def __init__(self, fx, fy, cx, cy, coeffs, rect):
        self.fx, self.fy, self.cx, self.cy = fx, fy, cx, cy
        c = list(coeffs) + [0.0] * (5 - len(coeffs))
        self.k1, self.k2, self.p1, self.p2, self.k3 = c
        self.coeffs = list(coeffs)
        self.R = np.asarray(rect, dtype=float).reshape(3, 3)  # raw -> rectified
        # largest undistorted radius for which the radial polynomial is still monotonic
        rr = np.linspace(0.0, 4.0, 40001)
        rd = rr * (1 + self.k1 * rr**2 + self.k2 * rr**4 + self.k3 * rr**6)
        d = np.diff(rd)
        bad = np.nonzero(d <= 0)[0]
        self.r_mono = rr[bad[0]] if len(bad) else rr[-1]

    def project_rect_rays(self, rays):
        """rays: (N,3) in the camera's RECTIFIED frame. Returns raw pixels (N,2) and a validity mask."""
        raw = rays @ self.R  # R^T applied to each row vector: X_raw = R^T X_rect
        z = raw[:, 2]
        ok = z > 1e-6
        zs = np.where(ok, z, 1.0)
        x = raw[:, 0] / zs
        y = raw[:, 1] / zs
        r2 = x * x + y * y
        ok &= np.sqrt(r2) < 0.98 * self.r_mono
        radial = 1 + self.k1 * r2 + self.k2 * r2**2 + self.k3 * r2**3
        xd = x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        u = self.fx * xd + self.cx
        v = self.fy * yd + self.cy
        return np.stack([u, v], axis=1), ok

    def table(self):
        return {
            "model": "plumb_bob",
            "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
            "coefficients": [float(c) for c in self.coeffs],
            "rectification": [float(v) for v in self.R.reshape(-1)],
        }


class Pinhole:
    """--lens none: the board's features are already rectified (v1)."""

    def __init__(self, f, cx, cy):
        self.f, self.cx, self.cy = f, cx, cy

    def project_rect_rays(self, rays):
        z = rays[:, 2]
        ok = z > 1e-6
        zs = np.where(ok, z, 1.0)
        u = self.cx + self.f * rays[:, 0] / zs
        v = self.cy + self.f * rays[:, 1] / zs
        return np.stack([u, v], axis=1), ok


# --------------------------------------------------------------------------------------
# path: curvature piecewise linear in arc length (straights, clothoids, arcs)
# --------------------------------------------------------------------------------------
class PathBuilder:
    def __init__(self, x, y, h):
        self.x, self.y, self.h = x, y, h
        self.segs = []   # (length, k0, k1, v_cruise)
        self.stops = []  # (s_position, dwell_seconds)
        self.s = 0.0

    @staticmethod
    def integrate(segs, x, y, h, ds=0.002):
        for (L, k0, k1, _v) in segs:
            n = max(1, int(math.ceil(L / ds)))
            d = L / n
            for i in range(n):
                sm = (i + 0.5) * d
                km = k0 + (k1 - k0) * sm / L if L > 0 else k0
                hm = h + km * d / 2
                x += d * math.cos(hm)
                y += d * math.sin(hm)
                h += km * d
        return x, y, h

    def _append(self, segs):
        self.x, self.y, self.h = self.integrate(segs, self.x, self.y, self.h)
        for sg in segs:
            self.segs.append(sg)
            self.s += sg[0]

    def straight(self, L, v):
        if L > 1e-6:
            self._append([(L, 0.0, 0.0, v)])

    def stop(self, dwell):
        self.stops.append((self.s, dwell))

    @staticmethod
    def turn_segs(angle, R, Lc, v):
        k = math.copysign(1.0 / R, angle)
        La = abs(angle) * R - Lc
        if La < 0:
            raise ValueError("clothoid too long for this turn")
        return [(Lc, 0.0, k, v), (La, k, k, v), (Lc, k, 0.0, v)]

    @classmethod
    def turn_displacement(cls, angle, R, Lc):
        x, y, _ = cls.integrate(cls.turn_segs(angle, R, Lc, 1.0), 0.0, 0.0, 0.0)
        return x, y  # forward, left

    def turn(self, angle, R, Lc, v):
        self._append(self.turn_segs(angle, R, Lc, v))

    def uturn(self, left, offset, Lc, v):
        """180 degree turn whose lateral displacement is exactly `offset`."""
        lo, hi = 0.3 * offset, 0.7 * offset
        sign = 1.0 if left else -1.0
        for _ in range(60):
            R = 0.5 * (lo + hi)
            _, lat = self.turn_displacement(sign * math.pi, R, Lc)
            if abs(lat) < offset:
                lo = R
            else:
                hi = R
        self.turn(sign * math.pi, 0.5 * (lo + hi), Lc, v)

    def straight_to_x(self, x_target, v):
        self.straight(abs(x_target - self.x), v)

    def straight_to_y(self, y_target, v):
        self.straight(abs(y_target - self.y), v)


def build_route(args, rng):
    """Serpentine aisles along hall x, stops, return along the end wall, first aisle again."""
    K = args.aisles
    d = rng.uniform(4.6, 5.6)          # aisle spacing, m
    L = args.aisle_length
    x_a = 14.0 + rng.uniform(-1, 1)
    x_b = x_a + L
    y0 = 10.0 + rng.uniform(-1, 1)
    v = args.speed
    Lc = 1.6                           # clothoid length: yaw acceleration ramp

    pb = PathBuilder(x_a - 3.0, y0, 0.0)
    pb.stop(args.initial_dwell)
    heading_plus = True
    for k in range(K):
        target = x_b if heading_plus else x_a
        remaining = abs(target - pb.x)
        n_stops = 1 + (rng.random() < 0.4)
        fr = np.sort(rng.uniform(0.2, 0.85, n_stops))
        done = 0.0
        for f_ in fr:
            pb.straight(f_ * remaining - done, v)
            pb.stop(rng.uniform(2.5, 6.0))
            done = f_ * remaining
        pb.straight(remaining - done, v)
        if k < K - 1:
            # serpentine: the next aisle is at +y
            pb.uturn(left=heading_plus, offset=d, Lc=Lc, v=v)
            heading_plus = not heading_plus
    aisle_end = pb.s
    revisit_start = None
    if not args.no_return:
        # turn towards -y (the wall side of aisle 0), drive along the end wall, turn into aisle 0
        R90 = 2.0
        turn1 = math.pi / 2 if not heading_plus else -math.pi / 2  # heading -x: left; +x: right
        pb.turn(turn1, R90, Lc, v)
        # now heading -y; turn 2 makes us head back into aisle 0
        turn2 = math.pi / 2 if not heading_plus else -math.pi / 2
        fwd, _lat = PathBuilder.turn_displacement(turn2, R90, Lc)
        pb.stop(rng.uniform(2.0, 4.0))
        pb.straight_to_y(y0 + fwd, v)
        pb.turn(turn2, R90, Lc, v)
        revisit_start = pb.s
        target = x_b if not heading_plus else x_a
        remaining = abs(target - pb.x)
        f_ = rng.uniform(0.3, 0.7)
        pb.straight(f_ * remaining, v)
        pb.stop(rng.uniform(2.5, 5.0))
        pb.straight((1 - f_) * remaining, v)
    pb.stop(args.final_dwell)
    info = {"aisle_spacing_m": d, "aisle_x": [x_a, x_b], "aisle0_y": y0, "aisles": K,
            "path_length_m": pb.s, "s_end_of_aisles": aisle_end, "s_revisit_start": revisit_start}
    return pb, info


def time_parametrise(pb, a_max, omega_max, smooth_s):
    """Speed profile along the path; returns t grid (s), v(t), omega(t) on the fine grid."""
    ds = 0.005
    # fine s grid with curvature and cruise speed
    s_nodes, k_nodes, v_nodes = [], [], []
    s0 = 0.0
    for (L, k0, k1, vc) in pb.segs:
        n = max(1, int(math.ceil(L / ds)))
        ss = np.linspace(0.0, L, n + 1)[:-1]
        s_nodes.append(s0 + ss)
        k_nodes.append(k0 + (k1 - k0) * ss / L if L > 0 else np.full_like(ss, k0))
        v_nodes.append(np.full_like(ss, vc))
        s0 += L
    s_nodes.append(np.array([s0]))
    k_nodes.append(np.array([0.0]))
    v_nodes.append(np.array([pb.segs[-1][3]]))
    S = np.concatenate(s_nodes)
    Kp = np.concatenate(k_nodes)
    Vc = np.concatenate(v_nodes)
    vlim = np.minimum(Vc, omega_max / np.maximum(np.abs(Kp), 1e-9))

    # legs between stops
    stop_pos = sorted(pb.stops)
    cuts = [0.0] + [p for p, _ in stop_pos] + [S[-1]]
    t_list, s_list = [], []
    t = 0.0
    dwell_at = {}
    for p, dwell in stop_pos:
        dwell_at[round(p, 6)] = dwell_at.get(round(p, 6), 0.0) + dwell
    boundaries = sorted(set(round(c, 6) for c in cuts))
    # dwell at the start (position 0) before moving
    t += dwell_at.get(0.0, 0.0)
    t_list.append(np.array([0.0, t]))
    s_list.append(np.array([0.0, 0.0]))
    for a, b in zip(boundaries[:-1], boundaries[1:]):
        if b - a < 1e-6:
            continue
        m = (S >= a - 1e-9) & (S <= b + 1e-9)
        ss = S[m]
        if ss[0] > a:
            ss = np.concatenate([[a], ss])
        if ss[-1] < b:
            ss = np.concatenate([ss, [b]])
        vl = np.interp(ss, S, vlim)
        vv = vl.copy()
        vv[0] = 0.0
        for i in range(1, len(ss)):
            vv[i] = min(vv[i], math.sqrt(vv[i - 1] ** 2 + 2 * a_max * (ss[i] - ss[i - 1])))
        vv[-1] = 0.0
        for i in range(len(ss) - 2, -1, -1):
            vv[i] = min(vv[i], math.sqrt(vv[i + 1] ** 2 + 2 * a_max * (ss[i + 1] - ss[i])))
        dss = np.diff(ss)
        # trapezoid in speed; where both ends are ~0 use the time of constant acceleration instead
        dt = np.where(vv[:-1] + vv[1:] > 1e-6, 2 * dss / np.maximum(vv[:-1] + vv[1:], 1e-6),
                      np.sqrt(2 * dss / a_max))
        tt = t + np.concatenate([[0.0], np.cumsum(dt)])
        t = tt[-1]
        t_list.append(tt)
        s_list.append(ss)
        dw = dwell_at.get(b, 0.0)
        if dw > 0:
            t_list.append(np.array([t + dw]))
            s_list.append(np.array([b]))
            t += dw
    T = np.concatenate(t_list)
    Sx = np.concatenate(s_list)
    order = np.argsort(T, kind="stable")
    T, Sx = T[order], Sx[order]
    # keep strictly increasing time
    keep = np.concatenate([[True], np.diff(T) > 1e-12])
    T, Sx = T[keep], Sx[keep]

    dt = FINE_DT_US * 1e-6
    n = int(math.ceil(T[-1] / dt)) + 1
    tg = np.arange(n) * dt
    sg = np.interp(tg, T, Sx)
    vg = np.gradient(sg, dt)
    vg[vg < 0] = 0.0
    # jerk limiting: smooth the speed with a Hann window (preserves stops and the distance)
    w = int(round(smooth_s / dt)) | 1
    win = np.hanning(w + 2)[1:-1]
    win /= win.sum()
    pad = w
    vpad = np.concatenate([np.zeros(pad), vg, np.zeros(pad)])
    vs = np.convolve(vpad, win, mode="same")
    tg = np.arange(len(vs)) * dt
    sg = np.concatenate([[0.0], np.cumsum(0.5 * (vs[1:] + vs[:-1]) * dt)])
    kg = np.interp(sg, S, Kp)
    wg = kg * vs
    return tg, vs, wg


def integrate_unicycle(tg, v, w, x0, y0, h0):
    dt = np.diff(tg)
    th = h0 + np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)])
    cx = v * np.cos(th)
    cy = v * np.sin(th)
    x = x0 + np.concatenate([[0.0], np.cumsum(0.5 * (cx[1:] + cx[:-1]) * dt)])
    y = y0 + np.concatenate([[0.0], np.cumsum(0.5 * (cy[1:] + cy[:-1]) * dt)])
    return x, y, th


# --------------------------------------------------------------------------------------
# world
# --------------------------------------------------------------------------------------
def build_hall(rng, args):
    Lx, Ly = args.hall_length, args.hall_width
    sx = rng.uniform(3.5, 5.0)
    sy = rng.uniform(3.5, 5.0)
    nx = int(Lx // sx)
    ny = int(Ly // sy)
    ox = (Lx - (nx - 1) * sx) / 2
    oy = (Ly - (ny - 1) * sy) / 2
    # pitched (gabled) roof: ridge along x at mid width; lamps hang below the deck
    z_eave = rng.uniform(6.6, 7.2)
    z_ridge = rng.uniform(8.4, 9.4)
    drop = rng.uniform(0.6, 0.9)

    def deck(y):
        return z_eave + (z_ridge - z_eave) * (1 - np.abs(y - Ly / 2) / (Ly / 2))

    pts = []
    for i in range(nx):
        for j in range(ny):
            x = ox + i * sx + np.clip(rng.normal(0, 0.2), -0.45, 0.45)
            y = oy + j * sy + np.clip(rng.normal(0, 0.2), -0.45, 0.45)
            z = deck(y) - drop + rng.normal(0, 0.04)
            pts.append(("lamp", x, y, z))
    # sprinkler heads: at the deck, between the lamps (cell centres and row midpoints)
    for i in range(nx - 1):
        for j in range(ny):
            if rng.random() < 0.85:
                x = ox + (i + 0.5) * sx + rng.normal(0, 0.1)
                y = oy + j * sy + rng.normal(0, 0.1) + sy * 0.5 * (j < ny - 1)
                z = deck(y) - 0.15 + rng.normal(0, 0.02)
                pts.append(("sprinkler", x, y, z))
    kinds = np.array([p[0] for p in pts])
    P = np.array([[p[1], p[2], p[3]] for p in pts])
    info = {"hall_length_m": Lx, "hall_width_m": Ly, "lamp_spacing_m": [sx, sy],
            "lamp_grid": [nx, ny], "deck_eave_m": z_eave, "deck_ridge_m": z_ridge,
            "lamp_drop_m": drop}
    return kinds, P, info


# --------------------------------------------------------------------------------------
# serialisation helpers
# --------------------------------------------------------------------------------------
def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        r = repr(float(v))
        if "e" not in r and "." not in r and "inf" not in r and "nan" not in r:
            r += ".0"
        return r
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def write_toml(rig, path):
    lines = ["# rig file written by scripts/indep_sim/hall.py (vehicle-interfaces.md section 3)"]

    def table(name, d):
        lines.append("")
        lines.append(f"[{name}]")
        for k, v in d.items():
            lines.append(f"{k} = {toml_value(v)}")

    for name in ["camera", "mount", "estimate", "prior", "noise", "vehicle"]:
        if name in rig:
            table(name, rig[name])
    if "lens" in rig:
        for side in ["left", "right"]:
            table(f"lens.{side}", rig["lens"][side])
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def packet(frame_counter, t_us, left, right, flags=0):
    """board-icd 3. left/right: lists of (x_q4, y_q4, r)."""
    nl, nr = len(left), len(right)
    body = struct.pack("<BBHHHIQ", 1, flags, nl, nr, 0, frame_counter & 0xFFFFFFFF, t_us)
    feats = b"".join(struct.pack("<HHi", x, y, r) for (x, y, r) in list(left) + list(right))
    data = body + feats
    crc = zlib.crc32(data) & 0xFFFFFFFF
    return SYNC + data + struct.pack("<I", crc)


ODOM_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "stereonav.Odometry",
    "description": "Robot-frame velocities (vehicle-interfaces.md section 2), held from t_us until the next sample.",
    "type": "object",
    "properties": {
        "t_us": {"type": "integer", "minimum": 0, "description": "odometry clock, microseconds"},
        "vx": {"type": "number", "description": "m/s, robot x (forward)"},
        "vy": {"type": "number", "description": "m/s, robot y (left)"},
        "vtheta": {"type": "number", "description": "rad/s, about robot z (up)"},
    },
    "required": ["t_us", "vx", "vy", "vtheta"],
}

RIG_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "stereonav.Rig",
    "description": "The rig file's tables (vehicle-interfaces.md section 3) as JSON; [lens.left] is lens.left.",
    "type": "object",
    "properties": {
        "camera": {"type": "object", "properties": {k: {"type": "number"} for k in
                                                    ["width", "height", "f", "cx", "cy", "baseline"]}},
        "mount": {"type": "object", "properties": {k: {"type": "number"} for k in
                                                   ["x", "y", "z", "roll", "pitch", "yaw"]}},
        "estimate": {"type": "object", "properties": {"parameters": {"type": "array", "items": {"type": "string"}}}},
        "prior": {"type": "object", "additionalProperties": {"type": "number"}},
        "noise": {"type": "object", "additionalProperties": {"type": "number"}},
        "vehicle": {"type": "object", "additionalProperties": {"type": "number"}},
        "lens": {"type": "object", "properties": {s: {"type": "object", "properties": {
            "model": {"type": "string"}, "fx": {"type": "number"}, "fy": {"type": "number"},
            "cx": {"type": "number"}, "cy": {"type": "number"},
            "coefficients": {"type": "array", "items": {"type": "number"}},
            "rectification": {"type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9}}}
            for s in ["left", "right"]}},
    },
    "required": ["camera", "mount", "noise"],
}


def truth_schema(title, desc):
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title,
            "description": desc, "type": "object"}


# --------------------------------------------------------------------------------------
# main
# --------------------------------------------------------------------------------------
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--memory-tau", type=float, default=0.0,
                    help="odometry errors: first-order Gauss-Markov with this time constant (s); 0 = white")
    ap.add_argument("--lens", choices=["radtan", "none"], default="radtan")
    ap.add_argument("--aisles", type=int, default=4)
    ap.add_argument("--aisle-length", type=float, default=40.0)
    ap.add_argument("--no-return", action="store_true", help="skip the return along the wall and the revisit")
    ap.add_argument("--speed", type=float, default=1.0)
    ap.add_argument("--initial-dwell", type=float, default=2.0)
    ap.add_argument("--final-dwell", type=float, default=2.0)
    ap.add_argument("--hall-length", type=float, default=80.0)
    ap.add_argument("--hall-width", type=float, default=56.0)
    ap.add_argument("--link-latency-ms", type=float, default=8.0,
                    help="recorder receive time of a packet after its exposure (MCAP log_time only)")
    ap.add_argument("--frame-counter-start", type=int, default=None)
    ap.add_argument("--compression", choices=["zstd", "lz4"], default="zstd")
    ap.add_argument("--mcap-chunk-size", type=int, default=256 * 1024)
    ap.add_argument("--spurious-rate", type=float, default=3.0, help="mean spurious features per image per frame")
    dg = ap.add_argument_group("diagnostics (idealised logs to locate a problem; not for evaluation)")
    dg.add_argument("--no-pixel-noise", action="store_true")
    dg.add_argument("--no-odom-noise", action="store_true")
    dg.add_argument("--nominal-vehicle", action="store_true", help="true vehicle parameters = nominal (1, 1, 0, 0)")
    dg.add_argument("--nominal-baseline", action="store_true", help="true baseline = nominal")
    dg.add_argument("--no-misses", action="store_true", help="no missed detections")
    args = ap.parse_args(argv)

    os.makedirs(args.out, exist_ok=True)
    ss = np.random.SeedSequence(args.seed)
    (rs_world, rs_route, rs_params, rs_lens, rs_odom, rs_feat, rs_stream) = [
        np.random.default_rng(s) for s in ss.spawn(7)]

    # ---------------- world and route (hall frame H) ----------------
    kinds, P_H, hall_info = build_hall(rs_world, args)
    pb, route_info = build_route(args, rs_route)
    tg, v_t, w_t = time_parametrise(pb, a_max=0.45, omega_max=0.45, smooth_s=0.6)
    # start pose of the route in H
    x_start, y_start = route_info["aisle_x"][0] - 3.0, route_info["aisle0_y"]
    xh, yh, hh = integrate_unicycle(tg, v_t, w_t, x_start, y_start, 0.0)

    # ---------------- parameters ----------------
    f_nom = float(np.round(rs_params.uniform(455.0, 465.0), 3))
    cx_nom, cy_nom = 376.0, 240.0
    B_nom = float(np.round(rs_params.uniform(0.11, 0.12), 4))
    prior = {"baseline": 0.0003, "odom_scale": 0.02, "odom_yaw_scale": 0.02,
             "odom_yaw_bias": 0.005, "time_offset": 0.03}
    B_true = B_nom + rs_params.normal(0.0, prior["baseline"])
    mount = {"x": float(np.round(rs_params.uniform(-0.25, 0.25), 3)),
             "y": float(np.round(rs_params.uniform(-0.1, 0.1), 3)),
             "z": float(np.round(rs_params.uniform(1.5, 2.0), 3)),
             "roll": float(np.round(rs_params.normal(0, 0.006), 4)),
             "pitch": float(np.round(rs_params.normal(0, 0.006), 4)),
             "yaw": float(np.round(rs_params.normal(0, 0.006), 4))}
    odom_scale = 1.0 + float(np.clip(rs_params.normal(0, 0.01), -0.02, 0.02))
    odom_yaw_scale = 1.0 + float(np.clip(rs_params.normal(0, 0.01), -0.02, 0.02))
    odom_yaw_bias = float(rs_params.choice([-1, 1]) * rs_params.uniform(0.001, 0.005))
    time_offset_us = int(rs_params.integers(10_000, 20_001))
    time_offset = time_offset_us * 1e-6
    sig_pix, sig_v, sig_w = 0.3, 0.02, 0.01
    if args.nominal_vehicle:
        odom_scale, odom_yaw_scale, odom_yaw_bias, time_offset_us = 1.0, 1.0, 0.0, 0
        time_offset = 0.0
    if args.nominal_baseline:
        B_true = B_nom

    R_RS = rot_z(mount["yaw"]) @ rot_y(mount["pitch"]) @ rot_x(mount["roll"])
    t_RS = np.array([mount["x"], mount["y"], mount["z"]])

    # ---------------- lenses ----------------
    lens_tables = None
    if args.lens == "radtan":
        def draw_lens(fx0, fy0, cx0, cy0, k1, k2):
            fx = float(np.round(fx0 + rs_lens.normal(0, 1.5), 3))
            fy = float(np.round(fx - (fx0 - fy0) + rs_lens.normal(0, 0.3), 3))
            cx = float(np.round(cx0 + rs_lens.normal(0, 4.0), 3))
            cy = float(np.round(cy0 + rs_lens.normal(0, 4.0), 3))
            co = [float(np.round(k1 + rs_lens.normal(0, 0.004), 5)),
                  float(np.round(k2 + rs_lens.normal(0, 0.003), 5)),
                  float(np.round(rs_lens.normal(0, 2e-4), 6)),
                  float(np.round(rs_lens.normal(0, 2e-4), 6))]
            return fx, fy, cx, cy, co
        # a common tilt of the pair plus a small relative rotation, as stereoRectify removes
        w_common = rs_lens.normal(0, 0.004, 3)
        w_rel = rs_lens.normal(0, 0.004, 3)
        R_left = rodrigues(w_common - 0.5 * w_rel)
        R_right = rodrigues(w_common + 0.5 * w_rel)
        L = draw_lens(458.7, 457.3, 367.2, 248.4, -0.283, 0.074)
        Rr = draw_lens(457.6, 456.1, 380.0, 255.2, -0.284, 0.075)
        cams = [Lens(*L, R_left), Lens(*Rr, R_right)]
        lens_tables = {"left": cams[0].table(), "right": cams[1].table()}
    else:
        cams = [Pinhole(f_nom, cx_nom, cy_nom), Pinhole(f_nom, cx_nom, cy_nom)]

    # ---------------- clocks ----------------
    # odometry clock (= recorder clock) starts at T0; the fine grid index i <-> T0 + i ms
    T0_us = 3_600_000_000 + int(rs_params.integers(0, 1000)) * 1000
    n_fine = len(tg)
    odom_phase_ms = int(rs_params.integers(0, 10))
    first_exposure_idx = 1000 + int(rs_params.integers(0, 50))  # 1 s of odometry before the first frame
    last_fine = n_fine - 1
    frame_idx = np.arange(first_exposure_idx, last_fine - 1000, FRAME_DT_US // FINE_DT_US)
    odom_idx = np.arange(odom_phase_ms, last_fine - 10, ODOM_DT_US // FINE_DT_US)
    n_frames = len(frame_idx)

    # world frame W = robot frame at the first stereo frame's exposure
    i0 = frame_idx[0]
    X0, Y0, H0 = xh[i0], yh[i0], hh[i0]
    Rz0T = rot_z(-H0)[:2, :2]

    def to_world_xy(x, y):
        d = np.stack([np.asarray(x) - X0, np.asarray(y) - Y0], axis=0)
        w = Rz0T @ d
        return w[0], w[1]

    xw, yw = to_world_xy(xh, yh)
    hw = hh - H0
    Pw = P_H.copy()
    Pw[:, 0], Pw[:, 1] = to_world_xy(P_H[:, 0], P_H[:, 1])

    # ---------------- odometry ----------------
    dtf = FINE_DT_US * 1e-6
    cum_v = np.concatenate([[0.0], np.cumsum(0.5 * (v_t[1:] + v_t[:-1]) * dtf)])
    cum_w = np.concatenate([[0.0], np.cumsum(0.5 * (w_t[1:] + w_t[:-1]) * dtf)])
    step = ODOM_DT_US // FINE_DT_US
    vx_true = (cum_v[odom_idx + step] - cum_v[odom_idx]) / (step * dtf)
    w_true = (cum_w[odom_idx + step] - cum_w[odom_idx]) / (step * dtf)
    vy_true = np.zeros_like(vx_true)
    n_odom = len(odom_idx)
    tau = args.memory_tau

    def noise_series(sigma, n):
        wn = rs_odom.normal(0.0, 1.0, n)
        if tau <= 0:
            return sigma * wn
        phi = math.exp(-(ODOM_DT_US * 1e-6) / tau)
        q = sigma * math.sqrt(1 - phi * phi)
        e = np.empty(n)
        e[0] = sigma * wn[0]
        for k in range(1, n):
            e[k] = phi * e[k - 1] + q * wn[k]
        return e

    ex = noise_series(sig_v, n_odom)
    ey = noise_series(sig_v, n_odom)
    ew = noise_series(sig_w, n_odom)
    if args.no_odom_noise:
        ex, ey, ew = 0 * ex, 0 * ey, 0 * ew
    vx_rep = odom_scale * vx_true + ex
    vy_rep = odom_scale * vy_true + ey
    w_rep = odom_yaw_scale * w_true + odom_yaw_bias + ew
    odom_t_us = T0_us + odom_idx * FINE_DT_US

    # ---------------- features per frame ----------------
    frame_counter0 = (int(rs_params.integers(0, 2**32)) if args.frame_counter_start is None
                      else args.frame_counter_start) & 0xFFFFFFFF
    exposure_us = T0_us + frame_idx * FINE_DT_US          # odometry clock
    board_t_us = exposure_us + time_offset_us              # board clock: exposed at t - time_offset
    is_lamp = kinds == "lamp"
    n_pts = len(Pw)
    brightness = np.where(is_lamp, rs_feat.lognormal(math.log(9e6), 0.45, n_pts),
                          rs_feat.lognormal(math.log(1.6e6), 0.35, n_pts))
    p_detect = np.where(is_lamp, 0.985, 0.90)
    margin = 6.0
    cnt_left = np.zeros(n_pts, int)
    cnt_right = np.zeros(n_pts, int)
    cnt_both = np.zeros(n_pts, int)
    cnt_det_both = np.zeros(n_pts, int)
    cnt_left_rect_outside = 0
    packets = []
    assoc = []
    stats = {"features_left": 0, "features_right": 0, "spurious": 0, "merged": 0, "missed": 0,
             "max_per_image": 0, "overflow_frames": 0}
    B_half = 0.5 * B_true
    for j in range(n_frames):
        i = frame_idx[j]
        X, Y, th = xw[i], yw[i], hw[i]
        c, s_ = math.cos(th), math.sin(th)
        dx = Pw[:, 0] - X
        dy = Pw[:, 1] - Y
        pR = np.stack([c * dx + s_ * dy, -s_ * dx + c * dy, Pw[:, 2]], axis=1)
        pS = (pR - t_RS) @ R_RS   # R_RS^T (p_R - t)
        near = (pS[:, 2] > 0.3) & (np.hypot(pS[:, 0], pS[:, 1]) < 3.0 * pS[:, 2])
        idx = np.nonzero(near)[0]
        per_cam = []
        vis = []
        for cam_i, sign in enumerate((+1.0, -1.0)):
            rays = pS[idx].copy()
            rays[:, 0] += sign * B_half     # left: xs + B/2 ; right: xs - B/2
            uv, ok = cams[cam_i].project_rect_rays(rays)
            ok &= (uv[:, 0] >= margin) & (uv[:, 0] <= WIDTH - 1 - margin) & \
                  (uv[:, 1] >= margin) & (uv[:, 1] <= HEIGHT - 1 - margin)
            vis.append(ok)
            per_cam.append(uv)
        cnt_left[idx[vis[0]]] += 1
        cnt_right[idx[vis[1]]] += 1
        both = vis[0] & vis[1]
        cnt_both[idx[both]] += 1
        if args.lens == "radtan":
            # how many visible left points fall outside the rectified image (alpha = 0 crop)
            rl = pS[idx[vis[0]]].copy()
            rl[:, 0] += B_half
            ul = f_nom * rl[:, 0] / rl[:, 2] + cx_nom
            vl = f_nom * rl[:, 1] / rl[:, 2] + cy_nom
            cnt_left_rect_outside += int(np.sum((ul < 0) | (ul > WIDTH - 1) | (vl < 0) | (vl > HEIGHT - 1)))
        cam_feats = []
        cam_ids = []
        detected = []
        for cam_i in range(2):
            ok = vis[cam_i]
            ids = idx[ok]
            uv = per_cam[cam_i][ok]
            det = rs_feat.random(len(ids)) < p_detect[ids]
            if args.no_misses:
                det[:] = True
            stats["missed"] += int(np.sum(~det))
            ids, uv = ids[det], uv[det]
            detected.append(set(ids.tolist()))
            dist = np.linalg.norm(pS[ids], axis=1)
            rr = brightness[ids] * (6.0 / dist) ** 2 * rs_feat.lognormal(0.0, 0.12, len(ids))
            uvn = uv + rs_feat.normal(0.0, sig_pix, uv.shape) * (0.0 if args.no_pixel_noise else 1.0)
            # spurious one-frame features (reflections, edges of racking, ...)
            n_sp = rs_feat.poisson(args.spurious_rate)
            sp_uv = np.stack([rs_feat.uniform(4.5, WIDTH - 5.5, n_sp), rs_feat.uniform(4.5, HEIGHT - 5.5, n_sp)], 1)
            sp_r = rs_feat.lognormal(math.log(7e5), 0.5, n_sp)
            stats["spurious"] += n_sp
            all_uv = np.concatenate([uvn, sp_uv])
            all_r = np.concatenate([rr, sp_r])
            all_id = np.concatenate([ids, -np.ones(n_sp, int)])
            # one feature per blob: the board's 3x3 suppression; blobs closer than ~3 px merge
            order = np.argsort(-all_r)
            kept = []
            for q in order:
                if all(abs(all_uv[q, 0] - all_uv[k, 0]) > 3 or abs(all_uv[q, 1] - all_uv[k, 1]) > 3 for k in kept):
                    kept.append(q)
                else:
                    stats["merged"] += 1
            feats = []
            for q in kept:
                u, v = all_uv[q]
                xi, yi = int(round(u)), int(round(v))
                ox = int(np.clip(round(16 * (u - xi)), -8, 8))
                oy = int(np.clip(round(16 * (v - yi)), -8, 8))
                if not (4 <= xi <= WIDTH - 5 and 4 <= yi <= HEIGHT - 5):
                    continue
                r = int(np.clip(round(all_r[q]), 262145, 2**31 - 1))
                feats.append((yi, xi, 16 * xi + ox, 16 * yi + oy, r, int(all_id[q])))
            feats.sort(key=lambda f_: (f_[0], f_[1]))   # raster order by integer (y, x)
            flag = 0
            if len(feats) > MAX_FEATURES:
                feats = feats[:MAX_FEATURES]
                flag = 1 << cam_i
            cam_feats.append(([(f_[2], f_[3], f_[4]) for f_ in feats], flag))
            cam_ids.append([f_[5] for f_ in feats])
            stats["max_per_image"] = max(stats["max_per_image"], len(feats))
        stats["features_left"] += len(cam_feats[0][0])
        stats["features_right"] += len(cam_feats[1][0])
        for pid in detected[0] & detected[1]:
            cnt_det_both[pid] += 1
        flags = cam_feats[0][1] | cam_feats[1][1]
        if flags:
            stats["overflow_frames"] += 1
        packets.append(packet(frame_counter0 + j, int(board_t_us[j]), cam_feats[0][0], cam_feats[1][0], flags))
        assoc.append((cam_ids[0], cam_ids[1]))

    # ---------------- rig ----------------
    rig = {
        "camera": {"width": WIDTH, "height": HEIGHT, "f": f_nom, "cx": cx_nom, "cy": cy_nom, "baseline": B_nom},
        "mount": mount,
        "estimate": {"parameters": ["baseline", "odom_scale", "odom_yaw_scale", "odom_yaw_bias", "time_offset"]},
        "prior": dict(prior),
        "noise": {"pixel": sig_pix, "velocity": sig_v, "yaw_rate": sig_w,
                  "velocity_tau": float(tau), "yaw_rate_tau": float(tau)},
        "vehicle": {"odom_scale": 1.0, "odom_yaw_scale": 1.0, "odom_yaw_bias": 0.0, "time_offset": 0.0},
    }
    if lens_tables:
        rig["lens"] = lens_tables
    write_toml(rig, os.path.join(args.out, "rig.toml"))

    # ---------------- MCAP ----------------
    stream = b"".join(packets)
    # split the byte stream into pieces of varying size, independent of packet boundaries
    cuts = [0]
    while cuts[-1] < len(stream):
        kind = rs_stream.random()
        size = int(rs_stream.integers(1, 64)) if kind < 0.15 else (
            int(rs_stream.integers(64, 1500)) if kind < 0.8 else int(rs_stream.integers(1500, 9000)))
        cuts.append(min(len(stream), cuts[-1] + size))
    # receive time of each byte: packet j arrives from exposure + latency at ~10 MB/s
    pkt_start = np.cumsum([0] + [len(p) for p in packets])
    lat_us = int(args.link_latency_ms * 1000)

    def byte_time_us(b):
        j = int(np.searchsorted(pkt_start, b, side="right") - 1)
        j = min(j, n_frames - 1)
        return int(exposure_us[j]) + lat_us + (b - int(pkt_start[j])) // 10

    msgs = []  # (log_time_us, order, topic, payload)
    for a, b in zip(cuts[:-1], cuts[1:]):
        msgs.append((byte_time_us(b - 1), 1, "/fpga/features", stream[a:b]))
    for k in range(n_odom):
        # a sample describes [t_k, t_k + 10 ms) and is available at the end of it
        msgs.append((int(odom_t_us[k]) + ODOM_DT_US + 500, 0, "/odom", json.dumps(
            {"t_us": int(odom_t_us[k]), "vx": float(vx_rep[k]), "vy": float(vy_rep[k]),
             "vtheta": float(w_rep[k])}).encode()))
    for j in range(n_frames):
        i = frame_idx[j]
        msgs.append((int(exposure_us[j]) + lat_us, 2, "/truth/pose", json.dumps(
            {"frame": (frame_counter0 + j) & 0xFFFFFFFF, "t_us": int(board_t_us[j]),
             "t_exposure_odom_us": int(exposure_us[j]),
             "x": float(xw[i]), "y": float(yw[i]), "theta": float(hw[i])}).encode()))
        msgs.append((int(exposure_us[j]) + lat_us, 3, "/truth/features", json.dumps(
            {"t_us": int(board_t_us[j]), "left_point_ids": assoc[j][0],
             "right_point_ids": assoc[j][1]}).encode()))
    for k in range(n_odom):
        msgs.append((int(odom_t_us[k]) + ODOM_DT_US + 500, 4, "/truth/odom", json.dumps(
            {"t_us": int(odom_t_us[k]), "vx": float(vx_true[k]), "vy": float(vy_true[k]),
             "vtheta": float(w_true[k])}).encode()))
    msgs.sort(key=lambda m: (m[0], m[1]))
    t_first = min(msgs[0][0], int(odom_t_us[0])) - 1000

    points_json = [{"id": int(n), "kind": str(kinds[n]), "x": float(Pw[n, 0]), "y": float(Pw[n, 1]),
                    "z": float(Pw[n, 2]), "frames_left": int(cnt_left[n]), "frames_right": int(cnt_right[n]),
                    "frames_both_raw": int(cnt_both[n]), "frames_detected_both": int(cnt_det_both[n])}
                   for n in range(n_pts)]
    true_camera = {"f": f_nom, "cx": cx_nom, "cy": cy_nom, "baseline": float(B_true),
                   "mount_x": mount["x"], "mount_y": mount["y"], "mount_z": mount["z"],
                   "mount_roll": mount["roll"], "mount_pitch": mount["pitch"], "mount_yaw": mount["yaw"]}
    true_vehicle = {"odom_scale": odom_scale, "odom_yaw_scale": odom_yaw_scale,
                    "odom_yaw_bias": odom_yaw_bias, "time_offset": time_offset}

    comp = CompressionType.ZSTD if args.compression == "zstd" else CompressionType.LZ4
    path = os.path.join(args.out, "hall.mcap")
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=args.mcap_chunk_size, compression=comp)
        w.start(profile="", library="indep_sim/hall.py")
        sid_odom = w.register_schema("stereonav.Odometry", "jsonschema", json.dumps(ODOM_SCHEMA).encode())
        sid_rig = w.register_schema("stereonav.Rig", "jsonschema", json.dumps(RIG_SCHEMA).encode())
        ch = {
            "/rig": w.register_channel("/rig", "json", sid_rig),
            "/fpga/features": w.register_channel("/fpga/features", "stereonav.fpga-link.v1", 0),
            "/odom": w.register_channel("/odom", "json", sid_odom),
        }
        for topic, title in [("/truth/pose", "indep_sim.TruthPose"), ("/truth/features", "indep_sim.TruthFeatures"),
                             ("/truth/odom", "indep_sim.TruthOdometry"), ("/truth/points", "indep_sim.TruthPoints"),
                             ("/truth/parameters", "indep_sim.TruthParameters")]:
            sid = w.register_schema(title, "jsonschema", json.dumps(truth_schema(title, "simulator ground truth")).encode())
            ch[topic] = w.register_channel(topic, "json", sid)
        seq = {k: 0 for k in ch}

        def put(topic, t_us, data):
            w.add_message(ch[topic], log_time=t_us * 1000, data=data, publish_time=t_us * 1000, sequence=seq[topic])
            seq[topic] += 1

        put("/rig", t_first, json.dumps(rig).encode())
        put("/truth/parameters", t_first, json.dumps({"camera": true_camera, "vehicle": true_vehicle}).encode())
        put("/truth/points", t_first, json.dumps({"points": [{k: p[k] for k in ("id", "kind", "x", "y", "z")}
                                                              for p in points_json]}).encode())
        for (t_us, _o, topic, data) in msgs:
            put(topic, t_us, data)
        w.finish()

    # ---------------- truth.json ----------------
    v_abs = v_t
    acc = np.gradient(v_abs, dtf)
    yacc = np.gradient(w_t, dtf)
    truth = {
        "generator": "scripts/indep_sim/hall.py",
        "args": vars(args),
        "world_frame": "robot frame at the exposure of the first stereo frame (vehicle-interfaces 1)",
        "clocks": {"time_offset_us": time_offset_us,
                   "note": "board t_us = odometry-clock exposure time + time_offset (vehicle-interfaces 1.2)"},
        "camera": true_camera,
        "camera_nominal": rig["camera"],
        "vehicle": true_vehicle,
        "prior": prior,
        "noise": rig["noise"],
        "lens": lens_tables,
        "hall": hall_info,
        "route": route_info,
        "hall_to_world": {"x0": float(X0), "y0": float(Y0), "theta0": float(H0)},
        "points": points_json,
        "frames": [{"frame": (frame_counter0 + j) & 0xFFFFFFFF, "t_us": int(board_t_us[j]),
                    "t_exposure_odom_us": int(exposure_us[j]),
                    "x": float(xw[frame_idx[j]]), "y": float(yw[frame_idx[j]]),
                    "theta": float(hw[frame_idx[j]])} for j in range(n_frames)],
        "log": {"n_frames": n_frames, "n_odom": n_odom, "first_frame_t_us": int(board_t_us[0]),
                "last_frame_t_us": int(board_t_us[-1]),
                "duration_s": (int(board_t_us[-1]) - int(board_t_us[0])) * 1e-6,
                "odom_first_t_us": int(odom_t_us[0]), "odom_last_t_us": int(odom_t_us[-1]),
                "stream_bytes": len(stream), "stream_messages": len(cuts) - 1,
                "frame_counter_start": frame_counter0},
        "stats": dict(stats, **{
            "lamps": int(np.sum(is_lamp)), "sprinklers": int(np.sum(~is_lamp)),
            "max_speed": float(np.max(v_t)), "max_accel": float(np.max(np.abs(acc))),
            "max_yaw_rate": float(np.max(np.abs(w_t))), "max_yaw_accel": float(np.max(np.abs(yacc))),
            "distance_m": float(cum_v[-1]),
            "left_visible_outside_rectified_image": cnt_left_rect_outside,
            "odom_error_rms": {"vx": float(np.std(ex)), "vy": float(np.std(ey)), "vtheta": float(np.std(ew))},
        }),
    }
    with open(os.path.join(args.out, "truth.json"), "w") as fh:
        json.dump(truth, fh)
    print(f"wrote {path}: {n_frames} frames ({truth['log']['duration_s']:.1f} s), {n_odom} odometry samples, "
          f"{len(cuts) - 1} stream messages, {len(stream)} bytes; {int(np.sum(is_lamp))} lamps, "
          f"{int(np.sum(~is_lamp))} sprinklers; distance {cum_v[-1]:.1f} m; "
          f"max v {np.max(v_t):.2f} m/s, a {np.max(np.abs(acc)):.2f} m/s^2, "
          f"w {np.max(np.abs(w_t)):.2f} rad/s, dw/dt {np.max(np.abs(yacc)):.2f} rad/s^2")
    return 0


if __name__ == "__main__":
    sys.exit(main())
