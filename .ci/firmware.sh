#!/usr/bin/env bash
# Firmware checks (issue 5): builds both firmware flavours, runs the firmware under QEMU
# against the host (bit-for-bit equality test), measures footprint and instruction counts
# and compares them with the recorded budget in firmware-example/budget.txt.
#
#   bash .ci/firmware.sh            # check (fails on a regression beyond 2 % or a bar)
#   bash .ci/firmware.sh --record   # rewrite firmware-example/budget.txt with the measurement
#
# Installs what is missing: the thumbv7em target, qemu-system-arm, binutils-arm-none-eabi.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }
TARGET=thumbv7em-none-eabihf
PROFILE=firmware
# Cargo's target directory: $CARGO_TARGET_DIR when set.
TARGET_DIR="${CARGO_TARGET_DIR:-target}"
OUT="$TARGET_DIR/firmware-elf"
BUDGET=firmware-example/budget.txt
TOLERANCE_PERCENT=2
mkdir -p "$OUT"

step "tools"
rustup target list --installed | grep -qx "$TARGET" || rustup target add "$TARGET"
missing=()
command -v qemu-system-arm >/dev/null || missing+=(qemu-system-arm)
command -v arm-none-eabi-size >/dev/null || missing+=(binutils-arm-none-eabi)
if ((${#missing[@]})); then
    apt-get -o DPkg::Lock::Timeout=600 update
    apt-get -o DPkg::Lock::Timeout=600 install -y "${missing[@]}"
fi

step "clippy (firmware, both boards)"
cargo clippy -p firmware-example --locked --target "$TARGET" --bins -- -D warnings
cargo clippy -p firmware-example --locked --target "$TARGET" --no-default-features --features stm32f411 -- -D warnings
cargo clippy -p microslam --locked --target "$TARGET" --features wire,defmt -- -D warnings

step "build: stm32f411"
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --no-default-features --features stm32f411
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/stm32f411.elf"

step "build: qemu (firmware and cost binaries)"
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bins
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/qemu.elf"
cp "$TARGET_DIR/$TARGET/$PROFILE/cost" "$OUT/cost.elf"
cp "$TARGET_DIR/$TARGET/$PROFILE/cost_grid" "$OUT/cost_grid.elf"

measured="$OUT/measured.txt"
: >"$measured"
record() { printf '%-34s %s\n' "$1" "$2" >>"$measured"; }
for board in qemu stm32f411; do
    read -r text data bss _ < <(arm-none-eabi-size "$OUT/$board.elf" | tail -1)
    record "${board}_flash_bytes" "$((text + data))"
    record "${board}_static_ram_bytes" "$((data + bss))"
done

step "QEMU: firmware equals the host bit for bit (EKF and grid drives, MRCLAM 6)"
log="$OUT/hil.log"
FIRMWARE_ELF="$(cd "$OUT" && pwd)/qemu.elf" cargo test -p microslam-replay-tests --locked \
    --test firmware_qemu -- --ignored --nocapture 2>&1 | tee "$log"
# The high-water mark of each QEMU run (EKF drive, grid drive): the larger one.
stack=$(sed -n 's/^firmware stack peak\( with grid\)\{0,1\}: \([0-9]*\) bytes$/\2/p' "$log" | sort -n | tail -1)
[[ -n "$stack" ]] || { echo "no stack figure in the HIL output" >&2; exit 1; }
record "qemu_stack_peak_bytes" "$stack"

step "QEMU: instructions per call (-icount shift=6)"
cost_log="$OUT/cost.log"
: >"$cost_log"
for elf in cost cost_grid; do
    timeout 600 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -display none -monitor none \
        -serial stdio -icount shift=6 -semihosting-config enable=on,target=native \
        -kernel "$OUT/$elf.elf" </dev/null | tee "$OUT/$elf.run.log"
    grep -qx done "$OUT/$elf.run.log" || { echo "$elf run did not finish" >&2; exit 1; }
    cat "$OUT/$elf.run.log" >>"$cost_log"
done
awk '/^ekf /{
        split($2, n, "="); split($3, p, "="); split($4, u, "="); split($5, a, "=");
        printf "%-34s %s\n", "ekf" n[2] "_predict_instructions", p[2];
        printf "%-34s %s\n", "ekf" n[2] "_update_instructions", u[2];
        printf "%-34s %s\n", "ekf" n[2] "_add_landmark_instructions", a[2];
    }
    /^grid /{
        split($2, p, "="); split($4, w, "=");
        printf "%-34s %s\n", "grid_p" p[2] "_b90_w9_step_instructions", w[2];
    }' "$cost_log" >>"$measured"

step "report"
# Per (3+2n)² covariance entries at 64 landmarks, and the exponent of a log-log fit over
# n = 16, 32, 64 (cost ∝ n^e). The update is two scalar (Bierman) updates of the packed
# L D Lᵀ factor in one pass: about 8 instructions per entry (docs/ekf-covariance.md).
awk '
    /_update_instructions/ {
        match($1, /^ekf[0-9]+/); n = substr($1, 4, RLENGTH - 3);
        c[n] = $2
    }
    END {
        sx = sy = sxx = sxy = 0; m = 0;
        for (k = 16; k <= 64; k *= 2) {
            x = log(k); y = log(c[k]); sx += x; sy += y; sxx += x * x; sxy += x * y; m++
        }
        e = (m * sxy - sx * sy) / (m * sxx - sx * sx);
        d = (3 + 2 * 64) ^ 2;
        # cost = a + b·k + q·k², k = 3 + 2n, through the three points (Cramer).
        k1 = 35; k2 = 67; k3 = 131; y1 = c[16]; y2 = c[32]; y3 = c[64];
        q = ((y3 - y1) / (k3 - k1) - (y2 - y1) / (k2 - k1)) / (k3 - k2);
        printf "EKF update at 64 landmarks: %d instructions = %.2f per (3+2n)^2 entry (bar <= 8); fitted exponent n^%.2f; quadratic term %.2f per entry\n",
            c[64], c[64] / d, e, q
        if (c[64] / d > 8) { print "FAIL: the EKF update of the firmware is over 8 instructions per entry"; exit 1 }
    }' "$measured"
awk '
    { v[$1] = $2 }
    END {
        ram = v["qemu_static_ram_bytes"] + v["qemu_stack_peak_bytes"];
        printf "static RAM + stack: %d bytes (bar <= 131072); flash: %d bytes (bar <= 98304)\n", ram, v["qemu_flash_bytes"];
        g = v["grid_p32_b90_w9_step_instructions"];
        if (g != "") printf "grid step P=32, 90 beams, 9x9: %d instructions (bar <= 1500000)\n", g;
        if (ram > 131072 || v["qemu_flash_bytes"] > 98304 || v["stm32f411_flash_bytes"] > 98304) {
            print "FAIL: over the STM32F411 memory bar"; exit 1
        }
    }' "$measured"

if [[ "${1:-}" == "--record" ]]; then
    {
        echo "# Footprint (bytes) and cost (instructions per call under QEMU -icount) of"
        echo "# firmware-example, profile '$PROFILE'. .ci/firmware.sh fails when a figure grows"
        echo "# more than $TOLERANCE_PERCENT % above this record. Rewrite with: bash .ci/firmware.sh --record"
        cat "$measured"
    } >"$BUDGET"
    echo "recorded $BUDGET"
    exit 0
fi

step "budget ($BUDGET, tolerance $TOLERANCE_PERCENT %)"
awk -v tol="$TOLERANCE_PERCENT" '
    FNR == NR { if ($0 !~ /^#/ && NF == 2) budget[$1] = $2; next }
    {
        name = $1; now = $2;
        if (!(name in budget)) { printf "NEW   %-34s %10d (not in the budget file)\n", name, now; next }
        was = budget[name]; seen[name] = 1;
        tag = (now == was) ? "same" : (now < was ? "less" : "MORE");
        if (now > was * (1 + tol / 100)) { tag = "FAIL"; bad = 1 }
        printf "%-5s %-34s %10d (budget %d)\n", tag, name, now, was
    }
    END {
        for (n in budget) if (!(n in seen)) { printf "GONE  %s\n", n }
        if (bad) { print "footprint/cost regression: fix it, or record the new figures deliberately (--record)"; exit 1 }
    }' "$BUDGET" "$measured"

step "firmware checks passed"
