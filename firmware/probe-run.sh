#!/usr/bin/env bash
# Cargo's runner for thumbv7em-none-eabihf (see .cargo/config.toml): flashes the ELF with
# probe-rs and streams its defmt logs. The chip is the one named on the embassy-stm32 line
# of firmware/Cargo.toml, so changing the chip there is the whole change.
# Needs probe-rs (`cargo install probe-rs-tools --locked`) and a debug probe.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
feature=$(grep -E '^embassy-stm32 *=' "$here/Cargo.toml" | grep -oE '"stm32[a-z0-9]+"' | head -n1 | tr -d '"')
case "$feature" in
    # probe-rs names the package too; the flash algorithm and memory map are the same
    # for every package of a part.
    stm32g491cc) chip=STM32G491CCUx ;; # UFQFPN48, the fingertip board
    stm32g431cb) chip=STM32G431CBUx ;; # UFQFPN48, the G431 the board began with
    stm32g474re) chip=STM32G474RETx ;; # LQFP64, NUCLEO-G474RE
    "") echo "probe-run.sh: no stm32 chip feature on the embassy-stm32 line of $here/Cargo.toml" >&2; exit 2 ;;
    *) chip=$(echo "$feature" | tr '[:lower:]' '[:upper:]') ;; # probe-rs accepts a unique prefix
esac
if ! command -v probe-rs >/dev/null; then
    echo "probe-run.sh: probe-rs not found: cargo install probe-rs-tools --locked" >&2
    exit 2
fi
exec probe-rs run --chip "$chip" "$@"
