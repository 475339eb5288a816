#!/usr/bin/env bash
# Regenerates the pictures of README.md (docs/images/*.png) by running the commands written under them in README.md,
# with the current build. The test crates/voxstream/tests/readme_images.rs runs the same commands and fails when a
# committed picture no longer matches; this script runs that test in its update mode. The MNI152 and frog pictures
# need the real data (bash scripts/fetch-real-data.sh).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
VOXSTREAM_UPDATE_README_IMAGES=1 cargo test --release -p voxstream --test readme_images -- --nocapture \
    readme_pictures_match_what_the_build_renders
