#!/bin/sh
# Rebuild the presets shipped in wbcgrade/color/presets_data/ from samples/.
# Run from the repository root: sh presets/build.sh
set -e
out=wbcgrade/color/presets_data
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
build() {  # name "description" photo...
    name=$1; description=$2; shift 2
    mkdir "$tmp/$name"
    for photo in "$@"; do cp "samples/$photo.jpg" "$tmp/$name/"; done
    wbcgrade preset build "$tmp/$name" -o "$out/$name.npz" --bins 32 --no-cache --overwrite \
        --description "$description"
}
build landscape "outdoor palettes: autumn valley, bridge, green field, sunset" \
    aitzgorri bridge seeding sunset
build warm "warm palettes: coffee, red flower, sunset" coffee flower sunset
build mixed "all sample photos but chelsea: space, coffee, flower and landscapes" \
    astronaut aitzgorri bridge coffee flower seeding sunset
