#!/usr/bin/env bash
# The whole test suite, runnable on a fresh Debian machine with only rustup/cargo and
# Python 3: installs what it needs (idempotently), then checks formatting, lints, host
# tests (which include the core on an emulated Cortex-M4 and the CAN codec against
# cantools) and the firmware's build and size budget.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n=== %s\n' "$*"; }
as_root() { if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi; }

step "toolchain: thumbv7em-none-eabihf, clippy, rustfmt, llvm-tools"
rustup target add thumbv7em-none-eabihf >/dev/null
rustup component add clippy rustfmt llvm-tools >/dev/null

step "system packages: qemu-system-arm, binutils-arm-none-eabi"
if ! command -v qemu-system-arm >/dev/null || ! command -v arm-none-eabi-objdump >/dev/null; then
    as_root apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
        qemu-system-arm binutils-arm-none-eabi
fi

step "flip-link (the firmware's linker: a stack overflow faults instead of corrupting RAM)"
command -v flip-link >/dev/null || cargo install flip-link --locked

step "python venv with cantools (.venv)"
if ! .venv/bin/python -c 'import cantools' 2>/dev/null; then
    python3 -m venv .venv
    .venv/bin/pip install -q cantools
fi

step "formatting"
cargo fmt --all --check

step "lints: host crates, and the core and the Cortex-M4 test program as built for the target"
cargo clippy --all-targets -- -D warnings
cargo clippy -p detector-core -p fingertip-qemu --target thumbv7em-none-eabihf -- -D warnings

step "docs build without warnings"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps -p detector-core -p detector-build -p fingertip-can -p fingertip -p host-tests -p firmware -p fingertip-tick --quiet

step "tests (host; the emulated Cortex-M4; cantools)"
export FINGERTIP_REQUIRE_PYTHON=1 FINGERTIP_REQUIRE_QEMU=1
cargo test

step "firmware for the STM32G491CC: release build without warnings, clippy, size budget"
bash firmware/check-size.sh
