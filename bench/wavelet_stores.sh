#!/usr/bin/env bash
# Stores with wavelet-coded bricks against zstd stores (issue 47): for each real volume, imports it with zstd (the
# default), the wavelet codec lossless, and the wavelet codec at the error bounds a uniform quantiser would give
# 60, 50 and 40 dB of data PSNR over the volume's value range (E = range·√3·10^(−dB/20), `max_error_for_psnr`);
# reports the bricks' bytes on disk, the import time, a converged 512² default render's time, and that render's
# PSNR against the zstd store's render.
#
#   bash bench/wavelet_stores.sh [VOXSTREAM_BINARY] [WORK_DIR]
#
# Needs data/real (scripts/fetch-real-data.sh) and data/venv's numpy (for the PSNR). Prints a Markdown table.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=$(realpath "${1:-target/release/voxstream}")
work=${2:-$(mktemp -d)}
mkdir -p "$work"
real=$PWD/data/real
python=${PYTHON:-data/venv/bin/python}

cases=(
    "mni|$real/mni152_t1.nii.gz"
    "skull|$real/skull_2.9.inr"
    "frog|$real/frog_tissues.vti"
    "liver|$real/liver.inr.gz"
)

shard_bytes() { find "$1" -path '*/c/*' -type f -printf '%s\n' | awk '{s += $1} END {print s + 0}'; }
level0_bytes() { find "$1/0" -path '*/c/*' -type f -printf '%s\n' | awk '{s += $1} END {print s + 0}'; }

echo "| volume | bricks | level-0 bytes | all levels | smaller than zstd | import s | render s | render PSNR |"
echo "|---|---|---|---|---|---|---|---|"
for case in "${cases[@]}"; do
    IFS='|' read -r name file <<<"$case"
    reference_bytes=; n=0
    for setting in zstd 0 60 50 40; do
        if [ "$setting" != zstd ] && [ "$setting" != 0 ]; then
            # The bound for this many dB, from the zstd store's value range.
            setting=$("$bin" info "$work/$name-zstd.zarr" --json | "$python" -c "
import json, math, sys
info = json.load(sys.stdin); lo, hi = info['value_range']
print(f'{(hi - lo) * math.sqrt(3) * 10 ** (-$setting / 20):.4g}')")
        fi
        store=$work/$name-$setting.zarr
        rm -rf "$store"
        if [ "$setting" = zstd ]; then
            flags=(--codec zstd); label="zstd"; n=1
        elif [ "$setting" = 0 ]; then
            flags=(--codec wavelet); label="wavelet, lossless"; n=2
        else
            flags=(--codec wavelet --max-error "$setting"); label="wavelet, max error $setting"
            case $((n++)) in 2) label="$label (60 dB)";; 3) label="$label (50 dB)";; 4) label="$label (40 dB)";; esac
        fi
        import_s=$( { /usr/bin/time -f %e "$bin" import "$file" --out "$store" --quiet "${flags[@]}" >/dev/null; } 2>&1 | tail -1)
        png=$work/$name-$setting.png
        render_s=$( { /usr/bin/time -f %e "$bin" render "$store" --width 512 --height 512 --out "$png" >/dev/null; } 2>&1 | tail -1)
        l0=$(level0_bytes "$store"); all=$(shard_bytes "$store")
        if [ "$setting" = zstd ]; then
            reference_bytes=$all; ratio="1.00×"; db="(reference)"
        else
            ratio=$(awk -v a="$reference_bytes" -v b="$all" 'BEGIN {printf "%.2f×", a / b}')
            db=$("$python" bench/lib/png_psnr.py "$work/$name-zstd.png" "$png" "$work/$name-$setting-difference.pgm")
            [ "$db" = inf ] && db="∞ (identical)" || db="$db dB"
        fi
        echo "| $name | $label | $l0 | $all | $ratio | $import_s | $render_s | $db |"
    done
done
