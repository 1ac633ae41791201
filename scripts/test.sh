#!/usr/bin/env bash
# The project's tests, runnable on a fresh machine with only Rust and Python:
#
#   bash scripts/test.sh          the fast tier, what CI runs (.ci/run): formatting, lints,
#                                 every Rust and Python test but the slow tier's, the no_std
#                                 proof, the Python stubs and types. Budget: 25 minutes cold on
#                                 the 2-core CI machine (docs/testing.md has where the time goes).
#   bash scripts/test.sh --slow   the slow tier: the long statistical runs and the replays of
#                                 the big scenarios that the fast tier leaves out (Rust tests
#                                 named `slow_*`, Python tests marked `slow`). Run it before
#                                 resolving an issue that touches an estimator.
#
# Both install the Python tools into .venv (in the background, while cargo works). Every step
# prints how long it took.
#
# One profile serves every step: the `ci` profile (Cargo.toml: the workspace and the numeric
# kernels optimised, the rest of the tree at opt-level 1, debug assertions and overflow checks
# on, no debug info) checks the code for clippy and builds the Rust tests, the `stereonav`
# binary the Python tests call, and the Python module, so the dependency tree is compiled once
# for all three (and its proc macros and build scripts once for all four).
set -euo pipefail
cd "$(dirname "$0")/.."

tier=fast
case "${1:-}" in
    "") ;;
    --slow) tier=slow ;;
    *)
        echo "usage: bash scripts/test.sh [--slow]" >&2
        exit 2
        ;;
esac

started=$SECONDS
step_started=$SECONDS
step_name=""
end_step() {
    if [ -n "$step_name" ]; then
        printf '    (%s: %d s)\n' "$step_name" $((SECONDS - step_started))
    fi
}
step() {
    end_step
    step_name="$*"
    step_started=$SECONDS
    printf '\n==> %s\n' "$*"
}
finish() {
    local status=$?
    if [ -n "${pip_pid:-}" ]; then
        kill "$pip_pid" 2> /dev/null || true
    fi
    end_step
    step_name=""
    if [ "$status" -eq 0 ]; then
        printf '\n==> all checks of the %s tier passed in %d s\n' "$tier" $((SECONDS - started))
    else
        printf '\n==> FAILED (exit %d) after %d s\n' "$status" $((SECONDS - started)) >&2
    fi
}
trap finish EXIT

PROFILE=ci
TARGET_DIR="${CARGO_TARGET_DIR:-target}"
# The test build: every library, binary and test of the workspace. The examples and benches are
# left out: clippy --all-targets checks that they compile, and nothing runs them here.
TARGETS="--workspace --locked --lib --bins --tests"
# The interpreter pyo3's build script configures itself for, the same in the test build as under
# maturin. (maturin also sets PYO3_BUILD_EXTENSION_MODULE, which the test build cannot: its test
# binaries link libpython. So maturin compiles pyo3 and the module again, about 25 s.)
export PYO3_PYTHON="$PWD/.venv/bin/python"
# The slow tier's Rust tests: every test whose name starts with `slow_` (in any module). No
# other test has `slow_` in its name.
SLOW_RUST='test(/(^|::)slow_/)'
# cargo-nextest runs the test binaries side by side (both cores busy to the end, each test's
# time shown); without it, cargo test runs the same tests.
if cargo nextest --version > /dev/null 2>&1; then
    nextest=yes
else
    nextest=no
    echo "cargo-nextest not found: cargo test runs the Rust tests instead" >&2
fi
rust_tests() { # rust_tests fast|slow|build
    if [ "$nextest" = yes ]; then
        case "$1" in
            build) cargo nextest run $TARGETS --cargo-profile "$PROFILE" --no-run ;;
            fast) cargo nextest run $TARGETS --cargo-profile "$PROFILE" --no-fail-fast -E "not $SLOW_RUST" ;;
            slow) cargo nextest run $TARGETS --cargo-profile "$PROFILE" --no-fail-fast --no-tests=warn -E "$SLOW_RUST" ;;
        esac
    else
        case "$1" in
            build) cargo test $TARGETS --profile "$PROFILE" --no-run ;;
            fast) cargo test $TARGETS --profile "$PROFILE" --no-fail-fast -- --skip slow_ ;;
            slow) cargo test $TARGETS --profile "$PROFILE" --no-fail-fast -- slow_ ;;
        esac
    fi
}

step "Python tools into .venv (pip in the background until the Python module's step)"
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
mkdir -p "$TARGET_DIR"
pip_log="$TARGET_DIR/pip-install.log"
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt \
    > "$pip_log" 2>&1 &
pip_pid=$!
wait_for_pip() {
    step "wait for the Python tools"
    local pid=$pip_pid
    pip_pid=""
    if ! wait "$pid"; then
        cat "$pip_log" >&2
        echo "pip install -r requirements-dev.txt failed" >&2
        return 1
    fi
    cat "$pip_log"
}

if [ "$tier" = fast ]; then
    step "cargo fmt --check"
    cargo fmt --all -- --check

    step "cargo clippy (-D warnings): the workspace, the firmware crates without std"
    cargo clippy --workspace --all-targets --locked --profile "$PROFILE" -- -D warnings
    cargo clippy -p harris-core -p fpga-link --no-default-features --locked --profile "$PROFILE" \
        -- -D warnings
    cargo clippy -p rig-model -p selfcal -p track -p vslam-ekf -p nav --no-default-features \
        --features alloc --locked --profile "$PROFILE" -- -D warnings
fi

step "build the Rust tests and the stereonav binary (profile $PROFILE)"
rust_tests build

# ---- issue 40: the board's HDL (hdl/, docs/hdl.md), a step of its own --------------------------
# hdl/sim.sh simulates the Verilog with Verilator (installed with apt-get when missing) and
# hdl/test.py compares it, case by case, with the stereonav binary just built (harris-core and
# fpga-link): fast tier about 15 s, slow tier (whole 752x480 frames) about a minute.
hdl_tests() {
    step "HDL: the board's Verilog simulated against harris-core and fpga-link (hdl/test.py, $tier tier)"
    if [ "$tier" = fast ]; then
        python3 hdl/test.py --stereonav "$TARGET_DIR/$PROFILE/stereonav"
    else
        python3 hdl/test.py --slow --stereonav "$TARGET_DIR/$PROFILE/stereonav"
    fi
}
# ---- end of issue 40's step ------------------------------------------------------------------

if [ "$tier" = fast ]; then
    step "Rust tests (the slow tier's left out) and doc tests"
    rust_tests fast
    cargo test --workspace --locked --profile "$PROFILE" --doc

    step "no_std proof: firmware crates and the C interface's firmware build linked into a #![no_std] staticlib, run from C through stereonav.h"
    cargo build --locked --manifest-path ci/nostd-proof/Cargo.toml --target-dir target/nostd-proof
    cc -std=c99 -Wall -Wextra -Werror -I crates/capi/include ci/nostd-proof/main.c \
        target/nostd-proof/debug/libnostd_proof.a -o target/nostd-proof/run
    target/nostd-proof/run
else
    step "Rust tests of the slow tier"
    rust_tests slow
fi
hdl_tests

wait_for_pip
step "Python module (maturin develop, profile $PROFILE, on the test build's compiled tree)"
.venv/bin/python scripts/check-module-features.py
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" \
    .venv/bin/maturin develop --profile "$PROFILE" --locked -m crates/py/Cargo.toml

# The command line the Python tests compare with: the binary the Rust tests were built with.
# (CARGO_TARGET_DIR may be absolute.)
case "$TARGET_DIR" in
    /*) export STEREONAV_BIN="$TARGET_DIR/$PROFILE/stereonav" ;;
    *) export STEREONAV_BIN="$PWD/$TARGET_DIR/$PROFILE/stereonav" ;;
esac
if [ "$tier" = fast ]; then
    step "pytest (the slow tier's left out)"
    # pytest exits 5 when it collects nothing; under `set -e` that fails the run, as it should.
    .venv/bin/python -m pytest crates/py/tests -q -m "not slow" --durations=15 -n auto

    step "Python stubs against the built module (mypy stubtest) and strict typing"
    (cd crates/py/python && ../../../.venv/bin/python -m mypy.stubtest stereonav)
    .venv/bin/python -m mypy --strict crates/py/python/stereonav
else
    step "pytest of the slow tier"
    .venv/bin/python -m pytest crates/py/tests -q -m slow --durations=15 -n auto
fi
