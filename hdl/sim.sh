#!/usr/bin/env bash
# Simulates the board's HDL (hdl/rtl/) on one image (board-icd.md section 4):
#
#   bash hdl/sim.sh IMAGE.pgm THRESHOLD MAX_FEATURES
#
# prints exactly what `stereonav harris IMAGE.pgm --threshold THRESHOLD --max-features
# MAX_FEATURES` prints: the header `x_q4,y_q4,r`, then the features in the board's order. The
# image (8-bit PGM; an 8-bit gray PNG is converted first) goes to both cameras of hdl/rtl/stereo_board.v, and the features are
# read back from the packet its encoder sends (CRC checked; both cameras must agree).
#
#   bash hdl/sim.sh --packet OUT THRESHOLD MAX_FEATURES T0_US PERIOD_US FIRST_FRAME LEFT RIGHT [...]
#
# writes the board's byte stream for stereo pairs, as `stereonav fpga emulate` does, and
# `bash hdl/sim.sh --build` only builds the simulation.
#
# The simulator is Verilator (Debian's package `verilator`, with g++ and make). When it is
# missing, the script installs it with apt-get if it runs as root, and otherwise says in one line
# what is missing. The simulation is built once and cached in hdl/build/ (rebuilt when hdl/rtl,
# hdl/sim or the Verilator version change). HDL_SIM_SEED=N (N > 0) makes the pixel stream and
# the link irregular and starts every register and memory with random bits (see
# hdl/sim/board_tb.cpp); the output must not change.
set -euo pipefail
hdl="$(cd "$(dirname "$0")" && pwd)"
build="$hdl/build/sim"

need_tools() {
    local missing=()
    command -v verilator > /dev/null 2>&1 || missing+=(verilator)
    command -v g++ > /dev/null 2>&1 || missing+=(g++)
    command -v make > /dev/null 2>&1 || missing+=(make)
    if [ ${#missing[@]} -eq 0 ]; then
        return 0
    fi
    if [ "$(id -u)" = 0 ] && command -v apt-get > /dev/null 2>&1; then
        echo "hdl/sim.sh: installing ${missing[*]} (Debian packages) with apt-get" >&2
        if ! (DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" > /dev/null 2>&1 ||
            { apt-get update -qq > /dev/null 2>&1 &&
                DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" > /dev/null 2>&1; }); then
            echo "hdl/sim.sh: missing ${missing[*]}, and apt-get install ${missing[*]} failed" >&2
            exit 127
        fi
        return 0
    fi
    echo "hdl/sim.sh: missing ${missing[*]}: install it with 'apt-get install ${missing[*]}' (Debian/Ubuntu)" >&2
    exit 127
}

build_simulation() {
    mkdir -p "$hdl/build"
    local key
    key="$({ verilator --version; cat "$hdl"/rtl/*.v "$hdl"/rtl/*.vh "$hdl"/sim/*.cpp "$0"; } | sha256sum | cut -c1-16)"
    if [ -x "$build/board_tb" ] && [ "$(cat "$build/key" 2> /dev/null)" = "$key" ]; then
        return 0
    fi
    # One build at a time (tests may call this script in parallel); the others wait for it.
    exec 9> "$hdl/build/.lock"
    flock 9
    if [ -x "$build/board_tb" ] && [ "$(cat "$build/key" 2> /dev/null)" = "$key" ]; then
        return 0
    fi
    echo "hdl/sim.sh: building the simulation with $(verilator --version) (once, cached in hdl/build/)" >&2
    local tmp="$hdl/build/sim.tmp"
    rm -rf "$tmp"
    mkdir -p "$tmp"
    local sources=(sdp_ram.v harris_sobel.v harris_window.v harris_response.v harris_subpixel.v
        harris_nms.v harris_detector.v packet_encoder.v stereo_board.v)
    if ! verilator --cc --exe --build -O3 --x-assign unique --x-initial unique \
        -Wall -Wno-WIDTH -Wno-UNUSEDPARAM -Wno-UNUSEDSIGNAL -Wno-CMPCONST \
        -I"$hdl/rtl" --top-module stereo_board -Mdir "$tmp" -o board_tb \
        -CFLAGS "-O2 -std=c++17" -j 2 \
        "${sources[@]/#/$hdl/rtl/}" "$hdl/sim/board_tb.cpp" > "$tmp/build.log" 2>&1; then
        cat "$tmp/build.log" >&2
        echo "hdl/sim.sh: the Verilator build failed (log above)" >&2
        exit 1
    fi
    echo "$key" > "$tmp/key"
    rm -rf "$build"
    mv "$tmp" "$build"
    flock -u 9
}

if [ "${1:-}" = "--build" ]; then
    need_tools
    build_simulation
    exit 0
fi
if [ "${1:-}" = "--packet" ]; then
    shift
    need_tools
    build_simulation
    exec "$build/board_tb" packet "$@"
fi
if [ $# -ne 3 ]; then
    echo "usage: bash hdl/sim.sh IMAGE.pgm THRESHOLD MAX_FEATURES" >&2
    echo "       bash hdl/sim.sh --packet OUT THRESHOLD MAX_FEATURES T0_US PERIOD_US FIRST_FRAME LEFT RIGHT [LEFT RIGHT ...]" >&2
    exit 2
fi
need_tools
build_simulation
# The testbench reads binary PGM; another image stereonav reads (an 8-bit gray PNG, an ASCII PGM)
# is converted first, and named as given in the messages.
if [ -f "$1" ] && [ -r "$1" ] && [ "$(head -c 2 "$1")" != P5 ]; then
    converted="$(mktemp "${TMPDIR:-/tmp}/hdl-sim.XXXXXX.pgm")"
    trap 'rm -f "$converted"' EXIT
    python3 "$hdl/sim/to_pgm.py" "$1" "$converted"
    "$build/board_tb" harris "$converted" "$2" "$3" "$1"
    exit
fi
exec "$build/board_tb" harris "$@"
