"""One scenario, many noise seeds: is a difference a bias or one draw?

`stereonav simulate SCENARIO --seed S` keeps the scenario's world (its lamps, path and vehicle
errors) and draws the noise again. Each log is replayed with `stereonav replay` (no flags, the
log's own rig unless --rig) and its SUMMARY.json's truth read back: the baseline's error in
its own sigma, the landmark RMS (and after the best similarity), the trajectory, lamps missed.
A single log's baseline error is one draw of a spread as wide as its sigma; a change that
moves it by a fraction of that is a bias only if it moves every seed alike.

    .venv/bin/python scripts/noise_seeds.py fixtures/scenarios/hall-radtan.toml --seeds 1-8
    .venv/bin/python scripts/noise_seeds.py SCENARIO --seeds 1,4 --stereonav BIN --keep DIR

Written for docs/vehicle.md, "The baseline's drift" (2026-12-07, session 23): the fixture
hall's landmark RMS is 14 to 56 mm over eight noise seeds of one build.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def parse_seeds(text: str) -> list[int]:
    """`1-8` (inclusive) or `1,4,7`."""
    if "-" in text:
        a, b = text.split("-", 1)
        return list(range(int(a), int(b) + 1))
    return [int(v) for v in text.split(",") if v]


def run_seed(binary: str, scenario: Path, seed: int, out: Path, rig: str | None) -> dict:
    """Simulates one seed and replays it; the row of the table."""
    log = out / f"seed-{seed}.mcap"
    summary = out / f"seed-{seed}.json"
    subprocess.run(
        [binary, "simulate", str(scenario), "--seed", str(seed), "--out", str(log)],
        check=True,
        capture_output=True,
    )
    cmd = [binary, "replay", str(log), "--summary", str(summary)]
    if rig:
        cmd += ["--rig", rig]
    subprocess.run(cmd, check=True, capture_output=True)
    d = json.loads(summary.read_text())
    truth = d.get("truth")
    if truth is None:
        raise SystemExit(f"{summary}: no truth in the summary (not a simulator log?)")
    err = truth["camera"]["baseline"]
    sigma = d["camera"]["baseline"]["sigma"]
    return {
        "seed": seed,
        "baseline_err_mm": err * 1e3,
        "baseline_sigma_mm": sigma * 1e3,
        "z": err / sigma if sigma > 0 else math.nan,
        "landmark_rms_mm": truth["landmark_rms_m"] * 1e3,
        "aligned_mm": truth["landmark_rms_aligned_m"] * 1e3,
        "ate_mm": truth["ate_rms_m"] * 1e3,
        "missed": truth["lamps_missed"],
        "matched": truth["landmarks_matched"],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", type=Path)
    ap.add_argument("--seeds", default="1-8")
    ap.add_argument("--stereonav", default=str(ROOT / "target/release/stereonav"))
    ap.add_argument("--rig", help="replay with this rig file instead of the log's /rig")
    ap.add_argument("--keep", type=Path, help="keep the logs and summaries here")
    a = ap.parse_args()
    if not a.scenario.exists():
        print(f"noise_seeds: {a.scenario}: no such scenario", file=sys.stderr)
        return 2
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = a.keep or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        print("seed  baseline err (sigma)    landmark RMS  aligned  trajectory  missed")
        for seed in parse_seeds(a.seeds):
            try:
                r = run_seed(a.stereonav, a.scenario, seed, out, a.rig)
            except subprocess.CalledProcessError as e:
                err = e.stderr.decode(errors="replace").strip().splitlines()
                print(f"noise_seeds: seed {seed}: {err[-1] if err else e}", file=sys.stderr)
                return 1
            rows.append(r)
            print(
                f"{seed:4d}  {r['baseline_err_mm']:+.3f} mm ({r['z']:+.2f})  "
                f"{r['landmark_rms_mm']:8.1f} mm  {r['aligned_mm']:5.1f} mm  "
                f"{r['ate_mm']:6.1f} mm  {r['missed']:5d}"
            )
    z = [r["z"] for r in rows]
    lm = [r["landmark_rms_mm"] for r in rows]
    print(
        f"baseline z: mean {statistics.fmean(z):+.2f}, RMS {math.sqrt(statistics.fmean(v * v for v in z)):.2f}; "
        f"landmark RMS: median {statistics.median(lm):.1f} mm, mean {statistics.fmean(lm):.1f} mm, "
        f"{sum(v <= 30.0 for v in lm)} of {len(lm)} at most 30 mm"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
