#!/usr/bin/env bash
# Constant-memory benchmark of the replay (docs/benchmarks.md, "A whole shift"): the warehouse
# loop of fixtures/scenarios/warehouse-shift.toml simulated for 1, 9 and 364 laps (79 s,
# 12 min, 8 h of data), each replayed with every output (EST.mcap, SUMMARY.json, TRAJ.csv);
# prints the log size, the replay's wall time, its speed and its peak resident memory.
#   bash scripts/bench_shift.sh [LAPS...]      (default: 1 9 364)
# Needs GNU time (/usr/bin/time). Writes into target/bench-shift/.
set -euo pipefail
cd "$(dirname "$0")/.."
laps=("$@")
[ ${#laps[@]} -gt 0 ] || laps=(1 9 364)
out=target/bench-shift
mkdir -p "$out"
cargo build --release --locked -p stereonav-cli --quiet
bin=target/release/stereonav
cp fixtures/scenarios/warehouse.rig.toml "$out/"
printf '%6s %10s %10s %10s %8s %10s\n' laps data_s log_MB replay_s speed peak_MiB
for n in "${laps[@]}"; do
    scenario="$out/shift-$n.toml"
    sed "s/^repeat = .*/repeat = $n/" fixtures/scenarios/warehouse-shift.toml > "$scenario"
    log="$out/shift-$n.mcap"
    [ -f "$log" ] || "$bin" simulate "$scenario" --out "$log" > /dev/null
    /usr/bin/time -f '%e %M' -o "$out/time-$n" "$bin" replay "$log" \
        --out "$out/est-$n.mcap" --summary "$out/summary-$n.json" --trajectory "$out/traj-$n.csv" \
        > "$out/replay-$n.txt" 2> "$out/replay-$n.err"
    read -r wall kb < "$out/time-$n"
    data_s=$(sed -n 's/.*(\([0-9.]*\) s of data).*/\1/p' "$out/replay-$n.txt")
    size=$(stat -c %s "$log")
    awk -v n="$n" -v d="$data_s" -v s="$size" -v w="$wall" -v kb="$kb" \
        'BEGIN { printf "%6d %10.0f %10.1f %10.1f %7.0fx %10.1f\n", n, d, s / 1e6, w, d / w, kb / 1024 }'
done
