#!/bin/sh
# Rebuild the natural (ungraded) palettes shipped in wbcgrade/color/data/natural.npz,
# the content model of look extraction (wbcgrade/color/look.py).
# Run from the repository root: sh presets/build_natural.sh PHOTO_FOLDER
# The folder's photos and their licences are listed in wbcgrade/color/data/NATURAL.md.
set -e
folder=${1:?usage: sh presets/build_natural.sh PHOTO_FOLDER}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for photo in "$folder"/*.jpg; do
    case $(basename "$photo") in seeding_full.jpg) ;; *) cp "$photo" "$tmp/" ;; esac
done
wbcgrade preset build "$tmp" -o wbcgrade/color/data/natural.npz --bins 32 --no-cache \
    --overwrite --description "palettes of ungraded photos (content model of look extraction)"
