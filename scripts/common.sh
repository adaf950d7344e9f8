# shellcheck shell=bash
# Shared by scripts/check and .ci/firmware.sh (sourced, not run).

# step TEXT: a heading, with the time this script has been running.
step() { printf '\n==> [%d:%02d] %s\n' $((SECONDS / 60)) $((SECONDS % 60)) "$*"; }

fail() {
    echo "FAILED: $*" >&2
    exit 1
}

# run_tests MIN COMMAND...: runs a `cargo test` command, then fails unless the test
# harnesses together reported at least MIN passed tests (a filter that matches nothing,
# a target that lost its tests or an `--ignored` run with nothing ignored all show up).
run_tests() {
    local min=$1
    shift
    local log
    log=$(mktemp)
    "$@" 2>&1 | tee "$log"
    local passed
    passed=$(sed -n 's/^test result: [a-zA-Z]*\. \([0-9][0-9]*\) passed.*/\1/p' "$log" |
        awk '{ s += $1 } END { print s + 0 }')
    rm -f "$log"
    ((passed >= min)) || fail "'$*' ran $passed tests, expected at least $min"
    echo "passed: $passed tests ($*)"
}

# apt_install PACKAGE...: installs Debian packages (root, or sudo when there is one).
apt_install() {
    local sudo=()
    ((EUID == 0)) || sudo=(sudo)
    "${sudo[@]}" apt-get -o DPkg::Lock::Timeout=600 update
    "${sudo[@]}" apt-get -o DPkg::Lock::Timeout=600 install -y --no-install-recommends "$@"
}

# rustup_targets TARGET...: adds the rustup targets that are not installed yet.
rustup_targets() {
    local installed
    installed=$(rustup target list --installed)
    for target in "$@"; do
        grep -qx "$target" <<<"$installed" || rustup target add "$target"
    done
}

# ensure_nightly: installs the nightly toolchain (rustup, profile minimal, under
# $RUSTUP_HOME, usually ~/.rustup/toolchains/) when there is none.
ensure_nightly() {
    if ! rustup run nightly rustc --version >/dev/null 2>&1; then
        echo "installing the nightly toolchain (rustup, profile minimal)"
        rustup toolchain install nightly --profile minimal ||
            fail "no nightly toolchain and rustup could not install one"
    fi
}
