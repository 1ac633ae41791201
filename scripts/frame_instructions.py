#!/usr/bin/env python3
"""The navigator's instructions per frame, counted exactly by callgrind (issue 38, item 4).

    python3 scripts/frame_instructions.py LOG.mcap [RIG.toml]

runs `target/release/stereonav replay` under `valgrind --tool=callgrind` with collection on only
inside `nav::Navigator::push_frame` and a profile dumped after each call, and prints the
instructions of a frame: mean, median, 99th percentile and worst, and the frames counted.
Instruction counts do not drift with the machine's load (docs/benchmarks.md). Build the
binary first: `cargo build --release -p stereonav-cli`.
"""
import glob
import os
import subprocess
import sys
import tempfile


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    binary = os.path.join(root, "target", "release", "stereonav")
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "cg.out")
        cmd = [
            "valgrind", "--tool=callgrind", "--collect-atstart=no",
            "--toggle-collect=nav::Navigator::push_frame",
            "--dump-after=nav::Navigator::push_frame",
            f"--callgrind-out-file={out}", binary, "replay", sys.argv[1],
        ]
        if len(sys.argv) == 3:
            cmd += ["--rig", sys.argv[2]]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        per_frame = []
        for path in glob.glob(out + ".*"):
            with open(path) as f:
                for line in f:
                    if line.startswith("totals:"):
                        per_frame.append(int(line.split()[1]))
                        break
    if not per_frame:
        sys.exit("no frame was counted")
    per_frame.sort()
    n = len(per_frame)
    print(f"{sys.argv[1]}: {n} frames; instructions per frame: mean {sum(per_frame) / n / 1e6:.3f} M, "
          f"median {per_frame[n // 2] / 1e6:.3f} M, p99 {per_frame[min(n - 1, n * 99 // 100)] / 1e6:.3f} M, "
          f"worst {per_frame[-1] / 1e6:.3f} M")


if __name__ == "__main__":
    main()
