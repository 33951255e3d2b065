#!/usr/bin/env bash
# Builds the board firmware for the STM32 in release (warnings are errors), runs clippy on
# it (CAN FD, and the classic-CAN build), and fails when it outgrows its budget: the
# application's 104 KiB of flash (memory.x: the detector slots and the store take the rest
# of the first 128 KiB) and 98 KiB of static RAM (of the STM32G491CC's 112 KiB, 52 KiB of
# it the flight recorder and 25 KiB the room of two detectors of 128 features, the one in
# service and a spare to load into; the rest, at least 14 KiB, is the stack, of which the
# boot path needs about 11). Prints the figures, and an estimate of the boot stack against
# the RAM left over.
#
# Needs: the thumbv7em-none-eabihf target, llvm-tools (`rustup component add llvm-tools`)
# and flip-link (`cargo install flip-link --locked`). Run from anywhere.
set -euo pipefail
cd "$(dirname "$0")/.."

FLASH_BUDGET=$((104 * 1024))
RAM_BUDGET=$((98 * 1024))
RAM_TOTAL=$((112 * 1024)) # STM32G491CC, memory.x

command -v flip-link >/dev/null || { echo "check-size: flip-link missing: cargo install flip-link --locked" >&2; exit 2; }
sysroot=$(rustc --print sysroot)
host=$(rustc -vV | sed -n 's/^host: //p')
tools="$sysroot/lib/rustlib/$host/bin"
[ -x "$tools/llvm-size" ] || { echo "check-size: llvm-size missing: rustup component add llvm-tools" >&2; exit 2; }

log=$(mktemp)
trap 'rm -f "$log"' EXIT
# Warnings in the firmware crate fail the build (cargo replays cached ones, so a
# rebuild-free run still sees them).
cargo fw --color never 2>&1 | tee "$log"
if grep -A3 '^warning' "$log" | grep -q -- '--> firmware/'; then
    echo "check-size: the firmware build has warnings" >&2
    exit 1
fi
cargo fw-clippy --color never -- -D warnings
# The classic-CAN build compiles and lints too (its size is the CAN FD build's or less).
cargo fw-clippy --color never --features classic-can -- -D warnings

target_dir=$(cargo metadata --format-version 1 --no-deps | sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
elf="$target_dir/thumbv7em-none-eabihf/firmware/fingertip-firmware"
sizes=$("$tools/llvm-size" -A "$elf")
section() { echo "$sizes" | awk -v s="$1" '$1 == s { print $2; f = 1 } END { if (!f) print 0 }'; }
flash=$(( $(section .vector_table) + $(section .text) + $(section .rodata) + $(section .data) ))
ram=$(( $(section .data) + $(section .bss) + $(section .uninit) ))

# The boot path's stack: the frames of main, setup, build_detector and load_detector
# (their `sub sp` and register pushes), the deepest chain at boot. An estimate: callees
# not inlined add a little.
frames=0
while read -r n; do
    frames=$((frames + n))
done < <("$tools/llvm-objdump" -d --no-show-raw-insn --demangle "$elf" | awk '
    /^[0-9a-f]+ <.*>:$/ { fn = $0; next }
    fn ~ /(__cortex_m_rt_main|fingertip_firmware::setup|build_detector|boot::load_detector|Detector::load_image|Detector::read_image)/ {
        if ($0 ~ /\tsub(\.w|w)?\tsp, (sp, )?#/) { v = $0; sub(/.*#/, "", v); print v }
        if ($0 ~ /\tpush(\.w)?\t\{/) { r = $0; gsub(/[^,]/, "", r); print 4 * (length(r) + 1) }
    }')
stack=$((RAM_TOTAL - ram))

kib() { awk -v b="$1" 'BEGIN { printf "%.1f KiB", b / 1024 }'; }
echo
echo "firmware: flash $flash B ($(kib "$flash")) of $(kib $FLASH_BUDGET); static RAM $ram B ($(kib "$ram")) of $(kib $RAM_BUDGET)"
echo "boot stack: about $frames B ($(kib "$frames")) needed, $stack B ($(kib "$stack")) free"
status=0
if [ "$flash" -gt "$FLASH_BUDGET" ]; then echo "check-size: flash over budget" >&2; status=1; fi
if [ "$ram" -gt "$RAM_BUDGET" ]; then echo "check-size: static RAM over budget" >&2; status=1; fi
# The Cortex-M4's floating-point unit is single precision: a double pulls in 2-3 KiB of
# soft-float routines (firmware/README.md, Size).
doubles=$("$tools/llvm-nm" "$elf" | awk '$3 ~ /^__aeabi_(d[a-z]|[a-z0-9]+2d$|d2)|^__[a-z]+df[0-9]$/ { print $3 }' | sort -u | tr '\n' ' ')
if [ -n "$doubles" ]; then
    echo "check-size: double-precision arithmetic in the image: $doubles" >&2
    status=1
fi
if [ "$frames" -gt "$stack" ]; then
    echo "check-size: the boot stack does not fit in the RAM left over: the image would fault at boot" >&2
    status=1
fi
exit $status
