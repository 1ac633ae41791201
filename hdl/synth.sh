#!/usr/bin/env bash
# Synthesises the board's HDL with Yosys for a Lattice ECP5 (synth_ecp5) and prints the
# resources, for the whole board (hdl/rtl/stereo_board.v: two detectors, the feature buffers and
# the packet encoder) and for one detector, at two line-buffer depths:
#
#   MAX_WIDTH=1024  the 752x480 sensor (the depth block RAM gives at 752 anyway)
#   MAX_WIDTH=4095  the widest image the ICD allows
#
#   bash hdl/synth.sh            the four syntheses, 2 to 7 minutes; reports in hdl/build/synth/
#   bash hdl/synth.sh --ice40    also places and routes each detector stage alone on an iCE40
#                                HX8K with Debian's nextpnr-ice40 (installed like yosys) and prints
#                                its maximum clock: a lower bound on the fabric's speed; 20 minutes
#
# Yosys is Debian's package `yosys`: when it is missing, the script installs it with apt-get if
# it runs as root, and otherwise says in one line what is missing. Place and route needs
# nextpnr-ecp5, which Debian (bookworm) does not package; when `nextpnr-ecp5` is on the PATH
# anyway, the whole board at MAX_WIDTH=1024 is also placed and routed on an LFE5U-45F and its
# maximum clock printed. docs/hdl.md records the results.
set -euo pipefail
hdl="$(cd "$(dirname "$0")" && pwd)"
out="$hdl/build/synth"
ice40=no
case "${1:-}" in
    "") ;;
    --ice40) ice40=yes ;;
    *)
        echo "usage: bash hdl/synth.sh [--ice40]" >&2
        exit 2
        ;;
esac

need() { # need COMMAND PACKAGE: install the Debian package when the command is missing
    command -v "$1" > /dev/null 2>&1 && return 0
    if [ "$(id -u)" = 0 ] && command -v apt-get > /dev/null 2>&1; then
        echo "hdl/synth.sh: installing $2 (Debian package) with apt-get" >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$2" > /dev/null 2>&1 ||
            { apt-get update -qq > /dev/null 2>&1 &&
                DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$2" > /dev/null 2>&1; } ||
            { echo "hdl/synth.sh: missing $1, and apt-get install $2 failed" >&2; exit 127; }
    else
        echo "hdl/synth.sh: missing $1: install it with 'apt-get install $2' (Debian/Ubuntu)" >&2
        exit 127
    fi
}
need yosys yosys
if [ "$ice40" = yes ]; then
    need nextpnr-ice40 nextpnr-ice40
fi
mkdir -p "$out"

sources=(sdp_ram.v harris_sobel.v harris_window.v harris_response.v harris_subpixel.v harris_nms.v
    harris_detector.v packet_encoder.v stereo_board.v)
sources=("${sources[@]/#/$hdl/rtl/}")

# The cells synth_ecp5 maps to, in the order of the table.
cells=(LUT4 CCU2C PFUMX L6MUX21 TRELLIS_DPR16X4 TRELLIS_FF DP16KD MULT18X18D ALU54B)

synthesise() { # synthesise TOP MAX_WIDTH NAME
    local top=$1 width=$2 name=$3
    # (Yosys's warnings, that small register arrays become registers, go to the log only.)
    yosys -q -l "$out/$name.log" -p "
        read_verilog -I $hdl/rtl ${sources[*]};
        chparam -set MAX_WIDTH $width $top;
        synth_ecp5 -top $top -json $out/$name.json;
        tee -q -o $out/$name.stat stat" > /dev/null 2>&1 ||
        { echo "hdl/synth.sh: yosys failed on $top: see $out/$name.log" >&2; exit 1; }
}

count() { # count STATFILE CELL
    awk -v cell="$2" '$1 == cell { n = $2 } END { print n + 0 }' "$1"
}

echo "Yosys $(yosys -V | awk '{print $2}'), synth_ecp5 (Lattice ECP5), reports in hdl/build/synth/"
printf '%-32s' "design"
for cell in "${cells[@]}"; do printf ' %s' "$cell"; done
printf ' %s\n' "LUT4-equivalents"
for config in "stereo_board 1024 board-1024" "stereo_board 4095 board-4095" \
    "harris_detector 1024 detector-1024" "harris_detector 4095 detector-4095"; do
    read -r top width name <<< "$config"
    started=$SECONDS
    synthesise "$top" "$width" "$name"
    printf '%-32s' "$top MAX_WIDTH=$width"
    for cell in "${cells[@]}"; do printf " %${#cell}d" "$(count "$out/$name.stat" "$cell")"; done
    # A CCU2C is two LUT4s with their carry logic; PFUMX and L6MUX21 use no LUT of their own.
    printf ' %16d' $(($(count "$out/$name.stat" LUT4) + 2 * $(count "$out/$name.stat" CCU2C)))
    printf '   (%d s)\n' $((SECONDS - started))
done

if command -v nextpnr-ecp5 > /dev/null 2>&1; then
    echo "nextpnr-ecp5: placing and routing stereo_board MAX_WIDTH=1024 on an LFE5U-45F (CABGA381)"
    nextpnr-ecp5 --45k --package CABGA381 --json "$out/board-1024.json" --freq 50 \
        --timing-allow-fail --log "$out/board-1024.nextpnr.log" > /dev/null 2>&1 || true
    grep -E "Max frequency for clock" "$out/board-1024.nextpnr.log" | tail -1 ||
        echo "nextpnr-ecp5 failed: see $out/board-1024.nextpnr.log"
else
    echo "nextpnr-ecp5 is not installed (Debian bookworm does not package it): no place and route, no maximum clock"
fi

if [ "$ice40" = yes ]; then
    echo "nextpnr-ice40: each stage alone on an iCE40 HX8K (ct256), MAX_WIDTH=1024, every port on a pin"
    for top in harris_sobel harris_window harris_response harris_nms; do
        started=$SECONDS
        params=""
        if [ "$top" != harris_response ]; then
            params="chparam -set MAX_WIDTH 1024 $top;"
        fi
        yosys -q -l "$out/ice40-$top.log" -p "
            read_verilog -I $hdl/rtl ${sources[*]};
            $params
            synth_ice40 -top $top -json $out/ice40-$top.json" > /dev/null 2>&1 ||
            { echo "hdl/synth.sh: yosys failed on $top: see $out/ice40-$top.log" >&2; exit 1; }
        nextpnr-ice40 --hx8k --package ct256 --json "$out/ice40-$top.json" --pcf-allow-unconstrained \
            --freq 25 --timing-allow-fail --log "$out/ice40-$top.nextpnr.log" > /dev/null 2>&1 || true
        printf '%-16s %s, %s, %s   (%d s)\n' "$top" \
            "$(grep -E 'ICESTORM_LC:' "$out/ice40-$top.nextpnr.log" | tail -1 | awk '{sub("/", "", $3); print $3, "logic cells"}')" \
            "$(grep -E 'ICESTORM_RAM:' "$out/ice40-$top.nextpnr.log" | tail -1 | awk '{sub("/", "", $3); print $3, "RAM blocks"}')" \
            "$(grep -E 'Max frequency for clock' "$out/ice40-$top.nextpnr.log" | tail -1 | sed 's/.*: //')" \
            $((SECONDS - started))
    done
fi
