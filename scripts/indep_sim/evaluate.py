#!/usr/bin/env python3
"""Run `stereonav replay` on a log written by hall.py and compare its output with the truth.

Usage: python evaluate.py DIR [--bin PATH] [--timeout S] [--no-run]

Reads DIR/hall.mcap, DIR/rig.toml, DIR/truth.json; writes DIR/SUMMARY.json, DIR/traj.csv,
DIR/map.bin (by the stack), DIR/replay.stdout, DIR/replay.stderr, DIR/time.txt and DIR/eval.json;
prints one table.  Nothing is skipped silently: every check that cannot be made is reported as such.
"""

import argparse
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np

# The stack's release binary in this repository's target directory (or $STEREONAV).
STACK = os.environ.get(
    "STEREONAV",
    os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "target", "release", "stereonav"),
)
MATCH_R = 0.10            # m
MAPPABLE_FRAMES = 20
CHI2_3DOF_3SIGMA = 14.1564  # chi-square quantile, 3 dof, p = 0.9973 (the 1-D 3 sigma probability)
CAMERA_PARAMS = ["f", "cx", "cy", "baseline", "mount_x", "mount_y", "mount_z",
                 "mount_roll", "mount_pitch", "mount_yaw"]
VEHICLE_PARAMS = ["odom_scale", "odom_yaw_scale", "odom_yaw_bias", "time_offset"]


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def run_stack(d, binary, timeout):
    outs = {k: os.path.join(d, v) for k, v in
            [("summary", "SUMMARY.json"), ("traj", "traj.csv"), ("map", "map.bin"), ("time", "time.txt")]}
    for p in outs.values():
        if os.path.exists(p):
            os.remove(p)
    cmd = [binary, "replay", os.path.join(d, "hall.mcap"), "--rig", os.path.join(d, "rig.toml"),
           "--summary", outs["summary"], "--trajectory", outs["traj"], "--save-map", outs["map"]]
    use_time = os.path.exists("/usr/bin/time")
    full = (["/usr/bin/time", "-v", "-o", outs["time"]] if use_time else []) + cmd
    t0 = time.monotonic()
    timed_out = False
    with open(os.path.join(d, "replay.stdout"), "wb") as so, open(os.path.join(d, "replay.stderr"), "wb") as se:
        proc = subprocess.Popen(full, stdout=so, stderr=se)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()          # our own child, by its handle
            rc = proc.wait()
            timed_out = True
    wall = time.monotonic() - t0
    res = {"command": " ".join(cmd), "wall_s": wall, "timed_out": timed_out, "peak_rss_mb": None,
           "exit_status": rc}
    if use_time and os.path.exists(outs["time"]):
        txt = open(outs["time"]).read()
        for line in txt.splitlines():
            line = line.strip()
            if line.startswith("Maximum resident set size"):
                res["peak_rss_mb"] = int(line.split(":")[-1]) / 1024.0
            if line.startswith("Exit status:"):
                res["exit_status"] = int(line.split(":")[-1])
            if line.startswith("Command terminated by signal"):
                res["signal"] = line
    elif not use_time:
        res["peak_rss_mb_note"] = "/usr/bin/time not available"
    return res


def fmt(x, nd=3):
    if x is None:
        return "n/a"
    if isinstance(x, float):
        if math.isnan(x):
            return "nan"
        if abs(x) >= 1e4 or (abs(x) < 1e-3 and x != 0):
            return f"{x:.3e}"
        return f"{x:.{nd}f}"
    return str(x)


def evaluate(d, run):
    rows = []       # (metric, value, note)
    problems = []
    ev = {"run": run}

    def row(metric, value, note=""):
        rows.append((metric, value, note))

    truth = json.load(open(os.path.join(d, "truth.json")))
    log = truth["log"]
    row("log", f"{log['n_frames']} frames, {log['duration_s']:.1f} s, seed {truth['args']['seed']}, "
        f"lens {truth['args']['lens']}, memory_tau {truth['args']['memory_tau']}", d)
    row("replay exit status", run.get("exit_status"), ("TIMED OUT " if run.get("timed_out") else "") +
        run.get("signal", ""))
    row("replay wall time [s]", fmt(run.get("wall_s"), 1))
    rtf = log["duration_s"] / run["wall_s"] if run.get("wall_s") else None
    row("real-time factor", fmt(rtf, 2), "log duration / wall time")
    row("peak memory [MB]", fmt(run.get("peak_rss_mb"), 1), run.get("peak_rss_mb_note", "/usr/bin/time -v"))
    ev["rtf"] = rtf

    spath = os.path.join(d, "SUMMARY.json")
    summary = None
    if not os.path.exists(spath):
        problems.append("SUMMARY.json was not written")
    else:
        try:
            summary = json.load(open(spath))
        except Exception as e:  # noqa: BLE001
            problems.append(f"SUMMARY.json unreadable: {e}")
    if summary is None:
        row("SUMMARY.json", "MISSING", "; ".join(problems))
        return rows, problems, ev

    for key in ["frames", "corrupt", "lost", "phase_switch_t_us", "pose", "camera", "vehicle", "landmarks"]:
        if key not in summary:
            problems.append(f"SUMMARY.json lacks '{key}'")
    # frames
    fr = summary.get("frames")
    row("frames (summary / written)", f"{fr} / {log['n_frames']}", "" if fr == log["n_frames"] else "MISMATCH")
    if fr != log["n_frames"]:
        problems.append(f"frames {fr} != {log['n_frames']} written")
    row("corrupt / lost", f"{summary.get('corrupt')} / {summary.get('lost')}", "expected 0 / 0")
    if summary.get("corrupt") not in (0,) or summary.get("lost") not in (0,):
        problems.append(f"corrupt={summary.get('corrupt')} lost={summary.get('lost')} (expected 0)")
    ps = summary.get("phase_switch_t_us", "ABSENT")
    if isinstance(ps, int):
        row("phase switch", f"{(ps - log['first_frame_t_us']) * 1e-6:.1f} s after first frame", f"t_us {ps}")
    else:
        row("phase switch", str(ps))

    # ---------------- landmarks ----------------
    pts = truth["points"]
    T = np.array([[p["x"], p["y"], p["z"]] for p in pts])
    kind = np.array([p["kind"] for p in pts])
    nboth = np.array([p["frames_both_raw"] for p in pts])
    mappable = nboth >= MAPPABLE_FRAMES
    lms = summary.get("landmarks", [])
    bad_lm = 0
    Lpos, Lsig, Lobs = [], [], []
    for lm in lms:
        try:
            Lpos.append([float(lm["x"]), float(lm["y"]), float(lm["z"])])
            s = lm.get("sigma")
            Lsig.append([float(v) for v in s] if s is not None and len(s) == 3 else [np.nan] * 3)
            Lobs.append(lm.get("observations"))
        except Exception:  # noqa: BLE001
            bad_lm += 1
    if bad_lm:
        problems.append(f"{bad_lm} landmark entries without x/y/z")
    L = np.array(Lpos).reshape(-1, 3)
    S = np.array(Lsig).reshape(-1, 3)
    nsig_missing = int(np.sum(np.any(~np.isfinite(S), axis=1))) if len(S) else 0
    if nsig_missing:
        problems.append(f"{nsig_missing} landmarks lack a usable sigma [sx, sy, sz]")
    row("landmarks in summary", len(L), f"{bad_lm} malformed" if bad_lm else "")
    nl = len(L)
    if nl:
        D = np.linalg.norm(L[:, None, :] - T[None, :, :], axis=2)   # (landmarks, points)
        within = D < MATCH_R
        cnt = within.sum(axis=0)                                     # per point
        nearest = np.argmin(D, axis=1)
        nearest_d = D[np.arange(nl), nearest]
        near_cnt = np.bincount(nearest, minlength=len(T))
        spurious = ~within.any(axis=1)
    else:
        cnt = np.zeros(len(T), int)
        near_cnt = np.zeros(len(T), int)
        spurious = np.zeros(0, bool)
        nearest_d = np.zeros(0)
    dup_a = cnt >= 2
    dup_b = near_cnt >= 2
    matched = mappable & (cnt == 1)
    missed = mappable & (cnt == 0)
    ev["landmarks"] = {}
    for k, label in [("lamp", "lamps"), ("sprinkler", "sprinkler heads")]:
        m = kind == k
        stats = {"mappable": int(np.sum(mappable & m)), "matched_exactly_one": int(np.sum(matched & m)),
                 "duplicated_within": int(np.sum(dup_a & m)), "duplicated_nearest": int(np.sum(dup_b & m)),
                 "missed": int(np.sum(missed & m)),
                 "mapped_not_mappable": int(np.sum((~mappable) & m & (cnt > 0)))}
        ev["landmarks"][k] = stats
        row(f"{label}: mappable (both raw >= {MAPPABLE_FRAMES} frames)", stats["mappable"],
            f"of {int(np.sum(m))} in hall; {int(np.sum(m & (nboth > 0)))} seen in both at least once")
        row(f"{label}: matched (exactly one landmark < {MATCH_R} m)", stats["matched_exactly_one"],
            f"{100.0 * stats['matched_exactly_one'] / max(1, stats['mappable']):.1f} % of mappable")
        row(f"{label}: duplicated", int(np.sum((dup_a | dup_b) & m)),
            f"{stats['duplicated_within']} with >=2 landmarks < {MATCH_R} m; "
            f"{stats['duplicated_nearest']} nearest true point of >=2 landmarks")
        row(f"{label}: missed (mappable, no landmark < {MATCH_R} m)", stats["missed"],
            f"+{stats['mapped_not_mappable']} mapped that were < {MAPPABLE_FRAMES} frames in both")
    row(f"spurious landmarks (no true point < {MATCH_R} m)", int(np.sum(spurious)),
        (f"their nearest true point: median {np.median(nearest_d[spurious]):.2f} m" if np.any(spurious) else ""))
    ev["spurious"] = int(np.sum(spurious))
    if np.any(missed) and nl:
        md = np.min(D[:, missed], axis=0)
        row("missed points: nearest landmark", f"median {np.median(md):.3f} m",
            f"{int(np.sum(md < 0.3))} of them have one < 0.30 m")

    if nl and np.any(matched):
        pidx = np.nonzero(matched)[0]
        lidx = np.array([np.nonzero(within[:, p])[0][0] for p in pidx])
        E = L[lidx] - T[pidx]
        Sg = S[lidx]
        err = np.linalg.norm(E, axis=1)
        rms = float(np.sqrt(np.mean(err ** 2)))
        rms_ax = np.sqrt(np.mean(E ** 2, axis=0))
        row("landmark RMS error over matched [m]", fmt(rms, 4),
            f"x {rms_ax[0]:.4f} y {rms_ax[1]:.4f} z {rms_ax[2]:.4f}; max {err.max():.4f}")
        ok = np.all(np.isfinite(Sg) & (Sg > 0), axis=1)
        if not np.all(ok):
            problems.append(f"{int(np.sum(~ok))} matched landmarks have no positive sigma; left out of the 3-sigma test")
        Z = E[ok] / Sg[ok]
        chi2 = np.sum(Z ** 2, axis=1)
        share_chi = float(np.mean(chi2 < CHI2_3DOF_3SIGMA)) if len(chi2) else None
        share_ax = np.mean(np.abs(Z) < 3, axis=0) if len(Z) else [None] * 3
        row("matched inside 3 sigma (chi2 3 dof < 14.16)", fmt(share_chi, 3),
            f"expected 0.997; mean chi2 {np.mean(chi2):.2f} (expected 3); n={len(chi2)}")
        row("matched inside 3 sigma per axis", f"x {share_ax[0]:.3f} y {share_ax[1]:.3f} z {share_ax[2]:.3f}",
            f"all three {np.mean(np.all(np.abs(Z) < 3, axis=1)):.3f}; "
            f"rms z-score x {np.sqrt(np.mean(Z[:, 0]**2)):.2f} y {np.sqrt(np.mean(Z[:, 1]**2)):.2f} "
            f"z {np.sqrt(np.mean(Z[:, 2]**2)):.2f}")
        row("matched landmark sigma (median) [m]",
            f"x {np.median(Sg[:, 0]):.4f} y {np.median(Sg[:, 1]):.4f} z {np.median(Sg[:, 2]):.4f}")
        ev["landmark_rms"] = rms
        ev["chi2_share"] = share_chi
        ev["axis_share"] = [float(v) for v in share_ax]
        ev["mean_chi2"] = float(np.mean(chi2))
    else:
        row("landmark RMS error over matched [m]", "n/a", "no matched landmarks")

    # diagnostics beyond the brief's table: every landmark against its nearest true point
    if nl:
        near = nearest_d < 0.5
        row("diag: landmarks with a true point < 0.5 m", int(np.sum(near)), f"of {nl}")
        if np.any(near):
            E = L[near] - T[nearest[near]]
            Sg = S[near]
            ok = np.all(np.isfinite(Sg) & (Sg > 0), axis=1)
            Z = E[ok] / Sg[ok]
            chi2 = np.sum(Z ** 2, axis=1)
            row("diag: those, RMS error / inside 3 sigma (chi2)",
                f"{np.sqrt(np.mean(np.sum(E ** 2, axis=1))):.4f} m / {np.mean(chi2 < CHI2_3DOF_3SIGMA):.3f}",
                f"mean error x {E[:, 0].mean():+.4f} y {E[:, 1].mean():+.4f} z {E[:, 2].mean():+.4f}; "
                f"mean chi2 {np.mean(chi2):.2f}")
            # the scale gauge: only baseline x odom_scale is observable (1.2); fit one scale about
            # the world origin (the rig at the first frame) and look at what is left
            tp = T[nearest[near]] - np.array([0, 0, truth["camera"]["mount_z"]])
            lp = L[near] - np.array([0, 0, truth["camera"]["mount_z"]])
            k = float(np.sum(tp * lp) / np.sum(tp * tp))
            res = lp - k * tp
            b_ratio = None
            cam = summary.get("camera") or {}
            if "baseline" in cam:
                b_ratio = cam["baseline"]["value"] / truth["camera"]["baseline"]
            row("diag: best map scale about the first rig position", f"{k:.5f}",
                f"estimated/true baseline = {fmt(b_ratio, 5)}; RMS residual after scale "
                f"{np.sqrt(np.mean(np.sum(res ** 2, axis=1))):.4f} m")
            ev["map_scale"] = k
            ev["all_near_rms"] = float(np.sqrt(np.mean(np.sum(E ** 2, axis=1))))
            ev["all_near_chi2_share"] = float(np.mean(chi2 < CHI2_3DOF_3SIGMA))
        mp = mappable & (np.min(D, axis=0) < 0.5)
        row("diag: mappable points with a landmark < 0.5 m", int(np.sum(mp)), f"of {int(np.sum(mappable))}")

    # ---------------- trajectory ----------------
    tpath = os.path.join(d, "traj.csv")
    tf = {f["t_us"]: f for f in truth["frames"]}
    if not os.path.exists(tpath):
        problems.append("traj.csv was not written")
        row("trajectory", "MISSING")
    else:
        with open(tpath) as fh:
            rd = csv.reader(fh)
            header = next(rd, None)
            recs = [r for r in rd if r]
        if header is None or [h.strip() for h in header[:4]] != ["t_us", "x", "y", "theta"]:
            problems.append(f"traj.csv header is {header}, contract says t_us,x,y,theta")
        ex, ey, eth, unmatched, unparsable = [], [], [], 0, 0
        for r in recs:
            try:
                t = int(r[0])
                x, y, th = float(r[1]), float(r[2]), float(r[3])
            except Exception:  # noqa: BLE001
                unparsable += 1
                continue
            f = tf.get(t)
            if f is None:
                unmatched += 1
                continue
            ex.append(x - f["x"])
            ey.append(y - f["y"])
            eth.append(float(wrap(th - f["theta"])))
        n_rows = len(recs)
        note = f"{n_rows} rows for {log['n_frames']} frames; {unmatched} rows at no frame time; {unparsable} unparsable"
        if n_rows != log["n_frames"] or unmatched or unparsable:
            problems.append("trajectory: " + note)
        if ex:
            ex, ey, eth = map(np.array, (ex, ey, eth))
            ep = np.hypot(ex, ey)
            row("trajectory RMS position [m]", fmt(float(np.sqrt(np.mean(ep ** 2))), 4),
                f"max {ep.max():.3f} m; " + note)
            row("trajectory RMS heading [deg]", fmt(float(np.degrees(np.sqrt(np.mean(eth ** 2)))), 3),
                f"max {np.degrees(np.abs(eth).max()):.3f} deg")
            ev["traj_rms"] = float(np.sqrt(np.mean(ep ** 2)))
            ev["traj_max"] = float(ep.max())
            ev["heading_rms_deg"] = float(np.degrees(np.sqrt(np.mean(eth ** 2))))
        else:
            row("trajectory RMS position [m]", "n/a", note)
    pose = summary.get("pose")
    if isinstance(pose, dict) and all(k in pose for k in ("t_us", "x", "y", "theta")):
        f = tf.get(int(pose["t_us"]))
        if f is None:
            row("final pose", "t_us not a frame time", str(pose))
        else:
            row("final pose error", f"{math.hypot(pose['x'] - f['x'], pose['y'] - f['y']):.4f} m, "
                f"{math.degrees(float(wrap(pose['theta'] - f['theta']))):.3f} deg", f"t_us {pose['t_us']}")
    else:
        problems.append(f"summary pose malformed: {pose}")

    # ---------------- parameters ----------------
    ev["params"] = {}
    est = ["baseline", "odom_scale", "odom_yaw_scale", "odom_yaw_bias", "time_offset"]
    for group, names, tv in [("camera", CAMERA_PARAMS, truth["camera"]), ("vehicle", VEHICLE_PARAMS, truth["vehicle"])]:
        g = summary.get(group) or {}
        missing = [n for n in names if n not in g]
        if missing:
            problems.append(f"summary '{group}' lacks {missing}")
        for n in names:
            if n not in g:
                continue
            e = g[n]
            try:
                val, sig = float(e["value"]), float(e["sigma"])
            except Exception:  # noqa: BLE001
                problems.append(f"summary {group}.{n} malformed: {e}")
                continue
            err = val - tv[n]
            if n in est:
                z = err / sig if sig > 0 else float("inf")
                row(f"{n}: (estimate - truth) / sigma", fmt(z, 2),
                    f"est {val:.6g} true {tv[n]:.6g} sigma {sig:.3g}")
                ev["params"][n] = {"est": val, "true": tv[n], "sigma": sig, "z": z}
                if not math.isfinite(z) or abs(z) > 3:
                    problems.append(f"{n} is {z:.1f} sigma off")
            elif abs(err) > 1e-9 or sig != 0:
                row(f"{n} (not estimated)", f"{val:.6g}", f"true {tv[n]:.6g}, sigma {sig:.3g}")
        extra = [n for n in g if n not in names]
        if extra:
            row(f"{group}: extra parameters", ", ".join(extra))
    return rows, problems, ev


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--bin", default=STACK)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--no-run", action="store_true", help="only evaluate the existing outputs")
    a = ap.parse_args()
    d = a.dir
    if a.no_run:
        prev = os.path.join(d, "eval.json")
        run = json.load(open(prev))["run"] if os.path.exists(prev) else {"wall_s": None, "exit_status": None}
    else:
        if not os.path.exists(a.bin):
            print(f"stack binary {a.bin} is missing", file=sys.stderr)
            return 2
        run = run_stack(d, a.bin, a.timeout)
    rows, problems, ev = evaluate(d, run)
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(str(r[1])) for r in rows)
    print(f"command: {run.get('command', '(not run)')}")
    print(f"{'metric':<{w0}} | {'value':<{w1}} | note")
    print("-" * (w0 + w1 + 30))
    for m, v, n in rows:
        print(f"{m:<{w0}} | {str(v):<{w1}} | {n}")
    if problems:
        print("problems:")
        for p in problems:
            print("  - " + p)
    err = open(os.path.join(d, "replay.stderr")).read() if os.path.exists(os.path.join(d, "replay.stderr")) else ""
    if err.strip():
        lines = err.strip().splitlines()
        print(f"stack stderr ({len(lines)} lines), last lines:")
        for line in lines[-5:]:
            print("  " + line)
    ev["rows"] = [[m, str(v), n] for m, v, n in rows]
    ev["problems"] = problems
    json.dump(ev, open(os.path.join(d, "eval.json"), "w"), indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
