#!/usr/bin/env bash
# Fuzzes every parser voxstream reads untrusted input with (the fuzz targets of fuzz/) for SECONDS each (default 60),
# after building them once. Prints, per target, how long it ran and libFuzzer's last coverage line (cov: edges,
# ft: features, corp: corpus size). A crash stops the script with libFuzzer's report; the input that crashed is in
# fuzz/artifacts/TARGET/ and belongs, once fixed, under crates/voxstream/tests/fuzz_regressions/TARGET/.
#
# cargo-fuzz needs nightly features (-Z flags, sanitizer coverage); on the stable toolchain RUSTC_BOOTSTRAP=1 unlocks
# them. Targets are built without a sanitizer (-s none): the workspace forbids unsafe code, so AddressSanitizer adds
# little but cost; failed huge allocations still abort (a crash to libFuzzer), and -rss_limit_mb catches large ones
# that succeed. `RUSTC_BOOTSTRAP=1 cargo fuzz run -s address TARGET` also works on stable, about 2x slower.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

seconds="${1:-60}"
cargo_fuzz_version="0.13.2"
if ! cargo fuzz --version 2>/dev/null | grep -q "$cargo_fuzz_version"; then
    cargo install cargo-fuzz --locked --version "$cargo_fuzz_version"
fi
export RUSTC_BOOTSTRAP=1
python3 scripts/fuzz_seeds.py fuzz/seeds

cargo fuzz build --fuzz-dir fuzz -O -s none
for target in $(cargo fuzz list --fuzz-dir fuzz); do
    mkdir -p "fuzz/corpus/$target" "fuzz/artifacts/$target"
    log="fuzz/artifacts/$target/last-run.log"
    started=$(date +%s)
    # -timeout: one input taking 10 s is a hang; -rss_limit_mb: 2 GiB is far above what any input of -max_len needs.
    if ! cargo fuzz run --fuzz-dir fuzz -O -s none "$target" "fuzz/corpus/$target" "fuzz/seeds/$target" -- \
        -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
        -artifact_prefix="fuzz/artifacts/$target/" >"$log" 2>&1; then
        tail -n 40 "$log"
        echo "fuzz: $target failed; the input is in fuzz/artifacts/$target/" >&2
        exit 1
    fi
    coverage=$(grep -E '^#[0-9]+' "$log" | tail -n 1 | sed -E 's/^(#[0-9]+)[[:space:]]+[A-Z]+[[:space:]]+/\1 /')
    printf '%-22s %4ss  %s\n' "$target" "$(($(date +%s) - started))" "$coverage"
done
