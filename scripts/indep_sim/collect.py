#!/usr/bin/env python3
"""One line per evaluated run directory (reads DIR/eval.json and DIR/truth.json written by
hall.py and evaluate.py).  Usage: python collect.py DIR [DIR ...]"""
import json
import os
import sys

PARAMS = ["baseline", "odom_scale", "odom_yaw_scale", "odom_yaw_bias", "time_offset"]


def main(dirs):
    hdr = (f"{'run':<14} {'tau':>4} {'lamps m/M':>9} {'spr m/M':>8} {'dup':>3} {'spur':>4} {'lmRMS':>6} "
           f"{'chi2<':>5} {'trajRMS':>7} {'scale':>7} {'RTF':>5} {'MB':>5} {'rc':>2} | "
           + " ".join(f"{p[:10]:>10}" for p in PARAMS) + " | B-Bnom/sig")
    print(hdr)
    for d in dirs:
        p = os.path.join(d, "eval.json")
        if not os.path.exists(p):
            print(f"{d:<14} no eval.json")
            continue
        ev = json.load(open(p))
        tr = json.load(open(os.path.join(d, "truth.json")))
        lm = ev.get("landmarks", {})
        la, sp = lm.get("lamp", {}), lm.get("sprinkler", {})
        dup = sum(max(v.get("duplicated_within", 0), v.get("duplicated_nearest", 0)) for v in lm.values())
        zs = []
        for q in PARAMS:
            e = ev.get("params", {}).get(q)
            zs.append(f"{e['z']:>+10.2f}" if e else f"{'n/a':>10}")
        b = ev.get("params", {}).get("baseline")
        bn = tr["camera_nominal"]["baseline"]
        bdev = f"{(b['est'] - bn) / tr['prior']['baseline']:+.2f}" if b else "n/a"

        def g(k, f="{:.4f}"):
            v = ev.get(k)
            return f.format(v) if isinstance(v, (int, float)) else "n/a"
        print(f"{os.path.basename(d.rstrip('/')):<14} {tr['args']['memory_tau']:>4} "
              f"{la.get('matched_exactly_one', 0):>4}/{la.get('mappable', 0):<4} "
              f"{sp.get('matched_exactly_one', 0):>3}/{sp.get('mappable', 0):<4} {dup:>3} {ev.get('spurious', 0):>4} "
              f"{g('landmark_rms'):>6} {g('chi2_share', '{:.3f}'):>5} {g('traj_rms'):>7} {g('map_scale', '{:.5f}'):>7} "
              f"{g('rtf', '{:.0f}'):>5} {ev['run'].get('peak_rss_mb') or 0:>5.0f} {ev['run'].get('exit_status')!s:>2} | "
              + " ".join(zs) + f" | {bdev}")


if __name__ == "__main__":
    main(sys.argv[1:])
