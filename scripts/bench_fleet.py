"""Benchmark of ``stereonav.fleet.replay_logs`` against a plain loop (issue 21).

Simulates ``N`` logs (default 100) of a scenario (default ``paper-square-realistic``, each a
92 s drive with self-calibration) with seeds ``0..N``, then times, in this process:

- the plain loop: ``stereonav.replay`` of each log, one after the other, and its row;
- ``replay_logs`` on a local cluster of ``--workers`` processes (default 2), the cluster's
  start and close included, and again with the cluster's start left out (a client given).

and checks that the two tables are equal. Prints a Markdown table for docs/benchmarks.md.

    .venv/bin/python scripts/bench_fleet.py [--logs N] [--workers W] [--scenario TOML]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import tempfile
import time

import distributed

import stereonav
from stereonav import fleet

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=100)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--scenario",
        type=pathlib.Path,
        default=ROOT / "fixtures" / "scenarios" / "paper-square-realistic.toml",
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        logs = []
        for seed in range(args.logs):
            log = pathlib.Path(tmp) / f"log-{seed:03}.mcap"
            stereonav.simulate(args.scenario, seed=seed).write_log(log)
            logs.append(str(log))

        start = time.perf_counter()
        rows = [fleet.summary_row(log, stereonav.replay(log).summary) for log in logs]
        loop_s = time.perf_counter() - start

        start = time.perf_counter()
        table = fleet.replay_logs(logs, n_workers=args.workers, progress=False)
        dask_s = time.perf_counter() - start

        with distributed.LocalCluster(
            n_workers=args.workers, threads_per_worker=1, dashboard_address=None
        ) as cluster, distributed.Client(cluster) as client:
            start = time.perf_counter()
            warm = fleet.replay_logs(logs, scheduler=client, progress=False)
            warm_s = time.perf_counter() - start

    expected = fleet._table(rows)
    for t in (table, warm):
        assert t.drop(columns="log").equals(expected.drop(columns="log")), "tables differ"
    print(f"{args.logs} logs of {args.scenario.name}, {args.workers} workers, "
          f"{os.cpu_count()} cores, {platform.processor() or platform.machine()}")
    print("| how | wall time | per log | speed-up |")
    print("|---|---|---|---|")
    print(f"| plain loop (`stereonav.replay` one by one) | {loop_s:.1f} s | {1e3 * loop_s / args.logs:.0f} ms | 1.00 |")
    print(f"| `replay_logs`, local cluster of {args.workers} started and closed | {dask_s:.1f} s | "
          f"{1e3 * dask_s / args.logs:.0f} ms | {loop_s / dask_s:.2f} |")
    print(f"| `replay_logs` on a running cluster of {args.workers} | {warm_s:.1f} s | "
          f"{1e3 * warm_s / args.logs:.0f} ms | {loop_s / warm_s:.2f} |")


if __name__ == "__main__":
    main()
