#!/usr/bin/env bash
# Firmware checks: builds both firmware flavours, runs the firmware under QEMU against the
# host (bit-for-bit equality tests), measures footprint and instruction counts and checks
# every figure against firmware-example/budget.txt.
#
#   bash .ci/firmware.sh            # check
#   bash .ci/firmware.sh --record   # rewrite the recorded figures of the budget file
#
# budget.txt has one line per figure: `name recorded limit`. Every measured figure must be
# at most `recorded` + 2 % (a regression shows) and at most `limit` when that is a number
# (a bar the README states; `-` = no bar beyond the 2 %). A figure in the file that was not
# measured, a measured figure missing from the file, an `error` line from a cost binary or
# a malformed line all fail. `--record` rewrites the `recorded` column and keeps the limits
# (a new figure gets `-`: give it its bar by hand).
#
# Installs what is missing: the thumbv7em target (rustup), qemu-system-arm and
# binutils-arm-none-eabi (apt-get, into /usr/bin).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/common.sh

TARGET=thumbv7em-none-eabihf
PROFILE=firmware
# Cargo's target directory: $CARGO_TARGET_DIR when set.
TARGET_DIR="${CARGO_TARGET_DIR:-target}"
OUT="$TARGET_DIR/firmware-elf"
mkdir -p "$OUT"
OUT="$(cd "$OUT" && pwd)" # absolute: the tests run from other folders
BUDGET=firmware-example/budget.txt
TOLERANCE_PERCENT=2
mkdir -p "$OUT"

step "tools"
rustup_targets "$TARGET"
missing=()
command -v qemu-system-arm >/dev/null || missing+=(qemu-system-arm)
command -v arm-none-eabi-size >/dev/null || missing+=(binutils-arm-none-eabi)
if ((${#missing[@]})); then
    echo "installing ${missing[*]} (apt-get)"
    apt_install "${missing[@]}"
fi
qemu-system-arm --version | head -1
arm-none-eabi-size --version | head -1

step "clippy (firmware, both boards)"
cargo clippy -p firmware-example --locked --target "$TARGET" --bins -- -D warnings
cargo clippy -p firmware-example --locked --target "$TARGET" --no-default-features --features stm32f411 -- -D warnings
cargo clippy -p firmware-example --locked --target "$TARGET" --no-default-features --features stm32f411,stm32-in-qemu -- -D warnings
cargo clippy -p firmware-example --locked --target "$TARGET" --no-default-features --features stm32f411,own-lidar -- -D warnings
cargo clippy -p firmware-example --locked --target "$TARGET" --bins --features building-slam -- -D warnings
cargo clippy -p firmware-example --locked --target "$TARGET" --no-default-features --features stm32f411,building-slam -- -D warnings
cargo clippy -p microslam --locked --target "$TARGET" --features wire,defmt -- -D warnings

step "build: stm32f411"
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --no-default-features --features stm32f411
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/stm32f411.elf"
# The same build for QEMU's netduinoplus2 (an STM32F405), which does not model the clock
# tree: the clocks stay at the reset HSI (feature stm32-in-qemu). Its QEMU test runs the
# STM32 code (stm32f4xx-hal's USART2 and GPIO) against the host, bit for bit.
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --no-default-features --features stm32f411,stm32-in-qemu
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/stm32-qemu.elf"
export STM32_QEMU_ELF="$OUT/stm32-qemu.elf"

step "build: qemu (firmware and cost binaries)"
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bins
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/qemu.elf"
cp "$TARGET_DIR/$TARGET/$PROFILE/cost" "$OUT/cost.elf"
cp "$TARGET_DIR/$TARGET/$PROFILE/cost_grid" "$OUT/cost_grid.elf"
cp "$TARGET_DIR/$TARGET/$PROFILE/cost_relocalize" "$OUT/cost_relocalize.elf"
cp "$TARGET_DIR/$TARGET/$PROFILE/cost_slam" "$OUT/cost_slam.elf"

# The firmware with the car model (feature `car`: the EKF moved by a car's speed and
# steering), for the car's HIL test. Built after the plain ELFs above were copied.
step "build: the firmware with the car model (qemu)"
cargo clippy -p firmware-example --locked --target "$TARGET" --bins --features car -- -D warnings
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bin firmware-example --features car
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/car.elf"
export CAR_ELF="$OUT/car.elf"

# The building-scale grid SLAM firmware (profile::Slam with loop closure as the grid
# estimator, keyframes in the QEMU flash stand-in; QEMU only). Built after the plain ELFs
# above were copied (the feature changes the build).
step "build: building-scale SLAM firmware (qemu)"
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bin firmware-example --features building-slam
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/slam.elf"
export SLAM_ELF="$OUT/slam.elf"
# The same firmware for the STM32F411 board: keyframes, map image and saved pose in the
# chip's own flash sectors (7, 6, 1–2; memory-stm32f411-slam.x keeps the code in 0 and
# 3–5). QEMU's netduinoplus2 models no flash interface: built and measured, not run.
cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --no-default-features --features stm32f411,building-slam
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/slam-stm32f411.elf"

# ---- Localizer firmware (map in flash) ----
# The map of a host grid-SLAM run on the Intel log (made here, never committed) is
# embedded with MICROSLAM_MAP: the firmware then carries the localizer instead of the
# grid SLAM. Built after the plain ELFs above were copied (the variable changes the build).
step "build: localizer firmware with the Intel map in flash (qemu, stm32f411)"
MAP_DIR="$OUT/intel-map"
cargo build --release -p host-sim --locked
"$TARGET_DIR/release/host-sim" -q replay --filter grid-slam --dataset carmen:intel/intel-raw-part.clf --out "$MAP_DIR"
MICROSLAM_MAP="$MAP_DIR/map.yaml" cargo clippy -p firmware-example --locked --target "$TARGET" --bins -- -D warnings
# The board's localizer reads its own lidar on USART1 (PA10, interrupt and ring); the same
# build for netduinoplus2 runs its QEMU test.
MICROSLAM_MAP="$MAP_DIR/map.yaml" cargo clippy -p firmware-example --locked --target "$TARGET" --no-default-features --features stm32f411,own-lidar -- -D warnings
MICROSLAM_MAP="$MAP_DIR/map.yaml" cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --no-default-features --features stm32f411,own-lidar
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/localizer-stm32f411.elf"
MICROSLAM_MAP="$MAP_DIR/map.yaml" cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --no-default-features --features stm32f411,stm32-in-qemu,own-lidar
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/localizer-stm32-qemu.elf"
export STM32_LOCALIZER_QEMU_ELF="$OUT/localizer-stm32-qemu.elf"
# The QEMU localizer reads its own lidar too (feature own-lidar: an LD06 on UART1).
MICROSLAM_MAP="$MAP_DIR/map.yaml" cargo clippy -p firmware-example --locked --target "$TARGET" --bins --features own-lidar -- -D warnings
MICROSLAM_MAP="$MAP_DIR/map.yaml" cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bin firmware-example --bin cost_grid --features own-lidar
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/localizer.elf"
# cost_grid with the map: the localizer's step on the Intel map (scans ray-cast in it).
cp "$TARGET_DIR/$TARGET/$PROFILE/cost_grid" "$OUT/cost_grid_map.elf"
export LOCALIZER_ELF="$OUT/localizer.elf" LOCALIZER_MAP="$MAP_DIR/map.yaml"
# The same firmware with the map of the simulator's office (a `host-sim sim` grid-SLAM
# run, made here): the relocalization test in the simulated office runs on it (QEMU only).
step "build: localizer firmware with the simulated office's map in flash (qemu)"
OFFICE_DIR="$OUT/office-sim"
"$TARGET_DIR/release/host-sim" -q sim --no-plots --out "$OFFICE_DIR"
MICROSLAM_MAP="$OFFICE_DIR/grid/slam/map.yaml" cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bin firmware-example
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/localizer-office.elf"
export OFFICE_LOCALIZER_ELF="$OUT/localizer-office.elf" OFFICE_LOCALIZER_MAP="$OFFICE_DIR/grid/slam/map.yaml"
# The same firmware with the board's own map of the Intel lab: the image the
# building-scale SLAM firmware writes into its flash at the end of the log (`SaveMap`),
# here from the same code on the host (`replay --loop-closure`, P = 32: bit for bit the
# device's, as the building-scale SLAM's HIL checks), its layers added by the build script.
step "build: localizer firmware with the board SLAM's own Intel map in flash (qemu)"
BOARD_MAP_DIR="$OUT/intel-board-map"
"$TARGET_DIR/release/host-sim" -q replay --filter grid-slam --dataset carmen:intel/intel-raw-part.clf \
    --particles 32 --loop-closure --no-plots --out "$BOARD_MAP_DIR"
MICROSLAM_MAP="$BOARD_MAP_DIR/map.bin" cargo build -p firmware-example --locked --target "$TARGET" --profile "$PROFILE" --bin firmware-example
cp "$TARGET_DIR/$TARGET/$PROFILE/firmware-example" "$OUT/localizer-board-map.elf"
export BOARD_MAP_LOCALIZER_ELF="$OUT/localizer-board-map.elf" BOARD_MAP_LOCALIZER_MAP="$BOARD_MAP_DIR/map.bin"
# ---- end localizer firmware ----

measured="$OUT/measured.txt"
: >"$measured"
record() { printf '%-40s %s\n' "$1" "$2" >>"$measured"; }
for board in qemu stm32f411 car localizer localizer-stm32f411 localizer-board-map; do
    read -r text data bss _ < <(arm-none-eabi-size "$OUT/$board.elf" | tail -1)
    record "${board//-/_}_flash_bytes" "$((text + data))"
    record "${board//-/_}_static_ram_bytes" "$((data + bss))"
done
read -r text data bss _ < <(arm-none-eabi-size "$OUT/slam.elf" | tail -1)
record "building_slam_flash_bytes" "$((text + data))"
record "building_slam_static_ram_bytes" "$((data + bss))"
# Its initial values in flash (.data): the SLAM's 112 KB static is all zero bytes
# (GraphSlam::zeroed), so it belongs in .bss; a non-zero byte in it would put its whole
# image here and in flash.
record "building_slam_data_bytes" "$data"
# The STM32F411 build: its code and constants (all but the vector table in sector 0) must
# fit sectors 3–5 (212 992 bytes; the linker refuses more), its static RAM beside the
# QEMU build's stack peak within 128 KB (below).
read -r text data bss _ < <(arm-none-eabi-size "$OUT/slam-stm32f411.elf" | tail -1)
vectors=$(arm-none-eabi-size -A "$OUT/slam-stm32f411.elf" | awk '$1 == ".vector_table" { print $2 }')
[[ -n "$vectors" ]] || fail "no .vector_table in slam-stm32f411.elf"
record "building_slam_stm32f411_code_bytes" "$((text + data - vectors))"
record "building_slam_stm32f411_static_ram_bytes" "$((data + bss))"

step "QEMU: firmware equals the host bit for bit (EKF and grid drives, MRCLAM 6)"
log="$OUT/hil.log"
# Every #[ignore]d test of firmware_qemu.rs needs QEMU: all of them must run and pass.
qemu_tests=$(grep -c '^#\[ignore' tests/tests/firmware_qemu.rs)
FIRMWARE_ELF="$(cd "$OUT" && pwd)/qemu.elf" run_tests "$qemu_tests" cargo test -p microslam-replay-tests --locked \
    --test firmware_qemu -- --ignored --nocapture 2>&1 | tee "$log"
# The high-water mark of each QEMU run (EKF drive, grid drive): the larger one.
stack=$(sed -n 's/^firmware stack peak\( with grid\)\{0,1\}: \([0-9]*\) bytes$/\2/p' "$log" | sort -n | tail -1)
[[ -n "$stack" ]] || fail "no stack figure in the HIL output"
record "qemu_stack_peak_bytes" "$stack"
# The localizer firmware's high-water mark (its own QEMU run in the same test binary).
lstack=$(sed -n 's/^firmware stack peak with localizer: \([0-9]*\) bytes$/\1/p' "$log" | sort -n | tail -1)
[[ -n "$lstack" ]] || { echo "no localizer stack figure in the HIL output" >&2; exit 1; }
record "localizer_stack_peak_bytes" "$lstack"
# The building-scale SLAM firmware's high-water mark (its QEMU run on the Intel log).
sstack=$(sed -n 's/^firmware stack peak with building slam: \([0-9]*\) bytes$/\1/p' "$log" | sort -n | tail -1)
[[ -n "$sstack" ]] || fail "no building-slam stack figure in the HIL output"
record "building_slam_stack_peak_bytes" "$sstack"
sstatic=$(awk '$1 == "building_slam_static_ram_bytes" { print $2 }' "$measured")
record "building_slam_ram_with_stack_bytes" "$((sstatic + sstack))"
# The board build runs the same session code; its stack is the QEMU run's.
bstatic=$(awk '$1 == "building_slam_stm32f411_static_ram_bytes" { print $2 }' "$measured")
record "building_slam_stm32f411_ram_with_stack_bytes" "$((bstatic + sstack))"
# What the RAM bar is about: static RAM plus the stack (the QEMU runs' peak for both).
for board in qemu stm32f411 localizer localizer_stm32f411 localizer_board_map; do
    static=$(awk -v n="${board}_static_ram_bytes" '$1 == n { print $2 }' "$measured")
    peak=$stack; [[ $board == localizer* ]] && peak=$lstack
    record "${board}_ram_with_stack_bytes" "$((static + peak))"
done

step "QEMU: instructions per call (-icount shift=6)"
cost_log="$OUT/cost.log"
: >"$cost_log"
for elf in cost cost_grid cost_grid_map cost_relocalize cost_slam; do
    timeout 600 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -display none -monitor none \
        -serial stdio -icount shift=6 -semihosting-config enable=on,target=native \
        -kernel "$OUT/$elf.elf" </dev/null | tee "$OUT/$elf.run.log"
    grep -qx "done" "$OUT/$elf.run.log" || fail "$elf run did not finish"
    if grep '^error' "$OUT/$elf.run.log" >&2; then fail "$elf reported an error"; fi
    cat "$OUT/$elf.run.log" >>"$cost_log"
done
# `ekf n=N key=value…` → ekfN_key_instructions for every key;
# `grid p=P beams=B window=W step=S …` → grid_pP_bB_wW_step_instructions (W × W shifts);
# `localizer …` → localizer_pP_bB_wW_…, `localizer_map …` → localizer_intel_pP_bB_wW_…;
# `ld06 bins=B …` → ld06_bB_packet_{mean,max}_instructions.
awk '/^ekf /{
        split($2, n, "=");
        for (i = 3; i <= NF; i++) { split($i, kv, "="); printf "%-40s %s\n", "ekf" n[2] "_" kv[1] "_instructions", kv[2] }
    }
    /^(grid|localizer|localizer_map) /{
        split($2, p, "="); split($3, b, "="); split($4, w, "="); split($5, s, "=");
        name = ($1 == "localizer_map") ? "localizer_intel" : $1;
        printf "%-40s %s\n", name "_p" p[2] "_b" b[2] "_w" w[2] "_step_instructions", s[2];
    }
    /^relocalize /{
        split($2, c, "="); split($6, n, "=");
        printf "%-40s %s\n", "relocalize_" c[2] "x" c[2] "_instructions", n[2];
    }
    /^slam /{
        for (i = 2; i <= NF; i++) { split($i, kv, "="); g[kv[1]] = kv[2] }
        pre = "slam_p" g["p"] "_b" g["beams"] "_n" g["nodes"];
        printf "%-40s %s\n", pre "_mean_step_instructions", g["mean"];
        printf "%-40s %s\n", pre "_max_step_instructions", g["max"];
        printf "%-40s %s\n", pre "_max_closure_instructions", g["max_closure"];
        printf "%-40s %s\n", pre "_max_keyframe_instructions", g["max_keyframe"];
        printf "%-40s %s\n", pre "_max_plain_instructions", g["max_plain"];
        printf "%-40s %s\n", pre "_max_old_map_instructions", g["max_old_map"];
        printf "%-40s %s\n", pre "_max_match_instructions", g["max_match"];
        printf "%-40s %s\n", pre "_max_solve_instructions", g["max_solve"];
        printf "%-40s %s\n", pre "_steps_over_10m", g["over_10m"];
    }
    /^slam_bytes=/{ split($0, kv, "="); printf "%-40s %s\n", "slam_estimator_bytes", kv[2] }
    /^slam_map /{
        for (i = 2; i <= NF; i++) { split($i, kv, "="); m[kv[1]] = kv[2] }
        printf "%-40s %s\n", "slam_map_image_instructions", m["instructions"];
        printf "%-40s %s\n", "slam_map_image_bytes", m["bytes"];
    }
    /^ld06 /{
        for (i = 2; i <= NF; i++) { split($i, kv, "="); l[kv[1]] = kv[2] }
        printf "%-40s %s\n", "ld06_b" l["bins"] "_packet_mean_instructions", l["packet_mean"];
        printf "%-40s %s\n", "ld06_b" l["bins"] "_packet_max_instructions", l["packet_max"];
    }
    /^relocalize_budget(_b45)? /{
        for (i = 2; i <= NF; i++) { split($i, kv, "="); f[kv[1]] = kv[2] }
        printf "%-40s %s\n", $1 "_" f["cells"] "x" f["cells"] "_instructions", f["instructions"];
    }' "$cost_log" >>"$measured"

# The building-scale SLAM probe's memory: the profile's estimator (`microslam::profile::Slam`,
# static) and the stack's peak over a drive that fills its graph; together, what a SLAM
# firmware needs besides its serial buffers (the keyframes are in flash).
slam_stack=$(sed -n 's/^stack_peak_bytes=\([0-9]*\)$/\1/p' "$OUT/cost_slam.run.log")
slam_bytes=$(sed -n 's/^slam_bytes=\([0-9]*\)$/\1/p' "$OUT/cost_slam.run.log")
[[ -n "$slam_stack" && -n "$slam_bytes" ]] || fail "no memory figures in the cost_slam output"
record "slam_stack_peak_bytes" "$slam_stack"
record "slam_estimator_with_stack_bytes" "$((slam_bytes + slam_stack))"

step "report"
# EKF updates per (3+2n)² covariance entry at 64 landmarks, and the exponent of a log-log
# fit over n = 16, 32, 64 (cost ∝ n^e). The bar (≤ 8 per entry: two scalar Bierman updates
# of the packed L D Lᵀ factor, docs/ekf-covariance.md) is the limit column of its line in
# the budget file: 8 · 131² = 137 288 instructions.
awk '
    /^ekf(16|32|64)_update(_[a-z]+)?_instructions / {
        match($1, /^ekf[0-9]+/); n = substr($1, 4, RLENGTH - 3);
        form = $1; sub(/^ekf[0-9]+_update_?/, "", form); sub(/_?instructions$/, "", form);
        if (form == "") form = "ldl";
        c[form, n] = $2; forms[form] = 1
    }
    END {
        for (form in forms) {
            if (!((form, 16) in c) || !((form, 32) in c) || !((form, 64) in c)) continue;
            sx = sy = sxx = sxy = 0; m = 0;
            for (k = 16; k <= 64; k *= 2) {
                x = log(k); y = log(c[form, k]); sx += x; sy += y; sxx += x * x; sxy += x * y; m++
            }
            e = (m * sxy - sx * sy) / (m * sxx - sx * sx);
            printf "EKF update %-9s at 64 landmarks: %d instructions = %.2f per (3+2n)^2 entry; fitted exponent n^%.2f\n",
                form, c[form, 64], c[form, 64] / (3 + 2 * 64) ^ 2, e
        }
    }' "$measured"

if [[ "${1:-}" == "--record" ]]; then
    new=$(mktemp)
    {
        sed -n '/^#/p' "$BUDGET"
        awk 'FNR == NR { if ($0 !~ /^#/ && NF >= 3) limit[$1] = $3; next }
            { printf "%-40s %-10s %s\n", $1, $2, (($1 in limit) ? limit[$1] : "-") }' "$BUDGET" "$measured"
    } >"$new"
    mv "$new" "$BUDGET"
    echo "recorded $BUDGET:"
    cat "$BUDGET"
    exit 0
fi

step "budget ($BUDGET: each figure ≤ recorded + $TOLERANCE_PERCENT % and ≤ its limit)"
awk -v tol="$TOLERANCE_PERCENT" -v budget="$BUDGET" '
    FNR == NR {
        if ($0 ~ /^#/ || NF == 0) next;
        if (NF != 3 || $2 !~ /^[0-9]+$/ || $3 !~ /^([0-9]+|-)$/) {
            printf "FAIL  %s line %d: expected `name recorded limit`, got: %s\n", budget, FNR, $0; bad = 1; next
        }
        was[$1] = $2; limit[$1] = $3; next
    }
    {
        name = $1; now = $2; seen[name] = 1;
        if (NF != 2 || now !~ /^[0-9]+$/) { printf "FAIL  measurement not a whole number: %s\n", $0; bad = 1; next }
        if (!(name in was)) { printf "FAIL  %-40s %10.0f not in %s (record it: --record)\n", name, now, budget; bad = 1; next }
        tag = (now == was[name]) ? "same" : (now < was[name] ? "less" : "MORE");
        why = "";
        if (now > was[name] * (1 + tol / 100)) why = why " over recorded + " tol " %";
        if (limit[name] != "-" && now > limit[name]) why = why " over the limit";
        if (why != "") { tag = "FAIL"; bad = 1 }
        printf "%-5s %-40s %10.0f (recorded %.0f, limit %s)%s\n", tag, name, now, was[name], limit[name], why
    }
    END {
        for (n in was) if (!(n in seen)) { printf "FAIL  %-40s not measured\n", n; bad = 1 }
        if (bad) { print "budget check failed: fix the regression, or re-record deliberately (bash .ci/firmware.sh --record)"; exit 1 }
    }' "$BUDGET" "$measured"

step "firmware checks passed"
