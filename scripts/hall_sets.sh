#!/usr/bin/env bash
# The comparison sets an estimator change is judged on (docs/halls.md, docs/benchmarks.md):
# the 17 hall-loop variants (fixtures/scenarios/hall-loop.toml with its `seed` and `[world]
# seed` raised by 0 to 8, and its noise alone reseeded with --seed 53 to 60), each simulated
# and replayed with no flags; then the hall Monte Carlo: 24 radtan halls with white odometry,
# with 0.6 s of odometry memory stated and unstated, and 8 fisheye halls white and unstated.
#   bash scripts/hall_sets.sh TAG [BIN_DIR]
# BIN_DIR holds `stereonav` and the `hall_mc` example (default: a release build of this
# checkout). Writes target/hall-sets/TAG-{loops,w24,t24,s24,fw,fs}.txt; compare two tags
# with `diff`. About 20 minutes on one core of the 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/.."
tag=${1:?usage: hall_sets.sh TAG [BIN_DIR]}
bin=${2:-}
if [ -z "$bin" ]; then
    cargo build --release --locked -p stereonav-cli -p replay --bins --example hall_mc --quiet
    bin=target/release
    hall_mc=$bin/examples/hall_mc
else
    hall_mc=$bin/hall_mc
    [ -x "$hall_mc" ] || hall_mc=$bin/examples/hall_mc
fi
out=target/hall-sets
logs=$out/loops
mkdir -p "$logs"
cp fixtures/scenarios/hall-loop.rig.toml "$logs/"
# The variants' logs are written once, by the binary given first; later tags replay them.
for k in 0 1 2 3 4 5 6 7 8; do
    log="$logs/w$k.mcap"
    [ -f "$log" ] && continue
    sed -e "s/^seed = 52$/seed = $((52 + k))/" -e "s/^seed = 3535$/seed = $((3535 + k))/" \
        fixtures/scenarios/hall-loop.toml > "$logs/w$k.toml"
    "$bin/stereonav" simulate "$logs/w$k.toml" --out "$log" > /dev/null
done
for s in 53 54 55 56 57 58 59 60; do
    log="$logs/n$s.mcap"
    [ -f "$log" ] || "$bin/stereonav" simulate fixtures/scenarios/hall-loop.toml --seed "$s" --out "$log" > /dev/null
done
for log in "$logs"/*.mcap; do
    printf '%s %s\n' "$(basename "$log")" \
        "$("$bin/stereonav" replay "$log" 2>&1 | grep "against the log's truth" || echo 'replay failed')"
done > "$out/$tag-loops.txt"
"$hall_mc" 24 11 --lens radtan > "$out/$tag-w24.txt" 2>&1
"$hall_mc" 24 11 --lens radtan --odometry-tau 0.6 > "$out/$tag-t24.txt" 2>&1
"$hall_mc" 24 11 --lens radtan --odometry-tau 0.6 --tau-unstated > "$out/$tag-s24.txt" 2>&1
"$hall_mc" 8 11 --lens fisheye > "$out/$tag-fw.txt" 2>&1
"$hall_mc" 8 11 --lens fisheye --odometry-tau 0.6 --tau-unstated > "$out/$tag-fs.txt" 2>&1
for f in loops w24 t24 s24 fw fs; do
    printf '%s: %s\n' "$f" "$(tail -n 1 "$out/$tag-$f.txt")"
done
