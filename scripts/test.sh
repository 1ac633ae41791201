#!/usr/bin/env bash
# The project's whole test suite, runnable on a fresh machine with only Rust and Python:
#   bash scripts/test.sh
# It installs its Python tools into .venv, then runs formatting, lints, every Rust test, the
# no_std proof of the firmware crates, and the Python tests against a fresh build of the module.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

step "Python tools into .venv"
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (-D warnings)"
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo clippy -p harris-core -p fpga-link --no-default-features --locked -- -D warnings
cargo clippy -p rig-model -p selfcal -p track -p vslam-ekf -p nav --no-default-features --features alloc --locked -- -D warnings

step "cargo test"
cargo test --workspace --locked

step "no_std proof: firmware crates linked into a #![no_std] staticlib with its own panic handler, run from C"
cargo build --locked --manifest-path ci/nostd-proof/Cargo.toml --target-dir target/nostd-proof
cc -Wall -Wextra -Werror ci/nostd-proof/main.c target/nostd-proof/debug/libnostd_proof.a \
    -o target/nostd-proof/run
target/nostd-proof/run

step "Python module (maturin develop --release) and pytest"
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" \
    .venv/bin/maturin develop --release --locked --quiet -m crates/py/Cargo.toml
# pytest exits 5 when it collects nothing; under `set -e` that fails the run, as it should.
.venv/bin/python -m pytest crates/py/tests -q

step "Python stubs against the built module (mypy stubtest) and strict typing"
(cd crates/py/python && ../../../.venv/bin/python -m mypy.stubtest stereonav)
.venv/bin/python -m mypy --strict crates/py/python/stereonav

step "all checks passed"
