#!/usr/bin/env python3
"""Self-check of a hall.py log, independent of the stack and of hall.py's forward code.

Reads DIR/hall.mcap back (own packet parser of board-icd 3), DIR/rig.toml (tomllib), and
DIR/truth.json; maps every feature that the truth associates with a point through the
INVERSE of section 1.1 (iterative undistortion, rectification, nominal f/cx/cy), triangulates
left/right with the true baseline in the rig frame, moves the point to the world with the
true pose at that frame, and reports the mean and RMS error against the true point.
It also integrates the log's odometry with the true V (section 2) and compares with the true poses.
Usage: python selfcheck.py DIR
"""
import json
import math
import struct
import sys
import tomllib
import zlib

import numpy as np
from mcap.reader import make_reader


def parse_stream(buf):
    out = []
    i = 0
    while True:
        j = buf.find(b"\x5a\xa5\x3c\xc3", i)
        if j < 0 or j + 28 > len(buf):
            break
        ver, flags, nl, nr, res, fc, t = struct.unpack_from("<BBHHHIQ", buf, j + 4)
        n = nl + nr
        end = j + 24 + 8 * n
        if ver != 1 or res != 0 or end + 4 > len(buf):
            i = j + 1
            continue
        crc = struct.unpack_from("<I", buf, end)[0]
        if zlib.crc32(buf[j + 4:end]) & 0xFFFFFFFF != crc:
            i = j + 1
            continue
        f = np.frombuffer(buf[j + 24:end], dtype=np.dtype([("x", "<u2"), ("y", "<u2"), ("r", "<i4")]))
        out.append((fc, t, f[:nl], f[nl:]))
        i = end + 4
    return out


def undistort(u, v, L):
    x0 = (u - L["cx"]) / L["fx"]
    y0 = (v - L["cy"]) / L["fy"]
    c = list(L["coefficients"]) + [0.0] * 5
    k1, k2, p1, p2, k3 = c[:5]
    x, y = x0.copy(), y0.copy()
    for _ in range(200):
        r2 = x * x + y * y
        rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x = (x0 - dx) / rad
        y = (y0 - dy) / rad
    R = np.array(L["rectification"]).reshape(3, 3)
    ray = np.stack([x, y, np.ones_like(x)], 1) @ R.T
    return ray[:, 0] / ray[:, 2], ray[:, 1] / ray[:, 2]


def main(d):
    rig = tomllib.load(open(f"{d}/rig.toml", "rb"))
    truth = json.load(open(f"{d}/truth.json"))
    cam = rig["camera"]
    f, cx, cy = cam["f"], cam["cx"], cam["cy"]
    B = truth["camera"]["baseline"]
    m = rig["mount"]

    def R(axis, a):
        c, s = math.cos(a), math.sin(a)
        return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
                "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
                "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]

    R_RS = R("z", m["yaw"]) @ R("y", m["pitch"]) @ R("x", m["roll"])
    t_RS = np.array([m["x"], m["y"], m["z"]])
    stream = bytearray()
    assoc = {}
    odom = []
    with open(f"{d}/hall.mcap", "rb") as fh:
        for _s, ch, msg in make_reader(fh).iter_messages():
            if ch.topic == "/fpga/features":
                stream += msg.data
            elif ch.topic == "/truth/features":
                a = json.loads(msg.data)
                assoc[a["t_us"]] = a
            elif ch.topic == "/odom":
                odom.append(json.loads(msg.data))
    pk = parse_stream(bytes(stream))
    frames = {fr["t_us"]: fr for fr in truth["frames"]}
    P = np.array([[p["x"], p["y"], p["z"]] for p in truth["points"]])
    errs = []
    for fc, t, left, right in pk:
        a = assoc[t]
        fr = frames[t]
        li = {pid: k for k, pid in enumerate(a["left_point_ids"]) if pid >= 0}
        ri = {pid: k for k, pid in enumerate(a["right_point_ids"]) if pid >= 0}
        common = sorted(set(li) & set(ri))
        if not common:
            continue
        ul = left["x"][[li[c] for c in common]] / 16.0
        vl = left["y"][[li[c] for c in common]] / 16.0
        ur = right["x"][[ri[c] for c in common]] / 16.0
        vr = right["y"][[ri[c] for c in common]] / 16.0
        if "lens" in rig:
            xl, yl = undistort(ul, vl, rig["lens"]["left"])
            xr, yr = undistort(ur, vr, rig["lens"]["right"])
        else:
            xl, yl = (ul - cx) / f, (vl - cy) / f
            xr, yr = (ur - cx) / f, (vr - cy) / f
        disp = xl - xr                        # = B / zs
        zs = B / disp
        xs = xl * zs - B / 2
        ys = 0.5 * (yl + yr) * zs
        pS = np.stack([xs, ys, zs], 1)
        pR = pS @ R_RS.T + t_RS
        c, s = math.cos(fr["theta"]), math.sin(fr["theta"])
        pW = np.stack([fr["x"] + c * pR[:, 0] - s * pR[:, 1], fr["y"] + s * pR[:, 0] + c * pR[:, 1], pR[:, 2]], 1)
        errs.append(pW - P[common])
    E = np.concatenate(errs)
    print(f"{len(pk)} packets parsed; {len(E)} stereo observations triangulated")
    print("mean error x y z [m]:", np.round(E.mean(0), 5), " median:", np.round(np.median(E, 0), 5))
    print("rms  error x y z [m]:", np.round(np.sqrt((E ** 2).mean(0)), 4))
    # odometry integration with the true V
    V = truth["vehicle"]
    off = int(round(V["time_offset"] * 1e6))
    od = sorted(odom, key=lambda o: o["t_us"])
    t = np.array([o["t_us"] for o in od], dtype=np.int64)
    vx = np.array([o["vx"] for o in od]) / V["odom_scale"]
    vy = np.array([o["vy"] for o in od]) / V["odom_scale"]
    w = (np.array([o["vtheta"] for o in od]) - V["odom_yaw_bias"]) / V["odom_yaw_scale"]
    # integrate piecewise-constant twists from the first frame's exposure
    fl = truth["frames"]
    X = Y = H = 0.0
    k = np.searchsorted(t, fl[0]["t_us"] - off, side="right") - 1
    tc = fl[0]["t_us"] - off
    errs = []
    for fr in fl[1:]:
        te = fr["t_us"] - off
        while tc < te:
            tn = min(te, t[k + 1] if k + 1 < len(t) else te)
            dt = (tn - tc) * 1e-6
            Hm = H + 0.5 * w[k] * dt
            X += dt * (math.cos(Hm) * vx[k] - math.sin(Hm) * vy[k])
            Y += dt * (math.sin(Hm) * vx[k] + math.cos(Hm) * vy[k])
            H += w[k] * dt
            tc = tn
            if k + 1 < len(t) and tc >= t[k + 1]:
                k += 1
        errs.append((math.hypot(X - fr["x"], Y - fr["y"]), H - fr["theta"]))
    e = np.array(errs)
    print(f"odometry dead reckoning with the true V over {len(fl)} frames: final position error "
          f"{e[-1, 0]:.3f} m, heading {math.degrees(e[-1, 1]):.3f} deg (noise only; 0 if noise-free)")


if __name__ == "__main__":
    main(sys.argv[1])
