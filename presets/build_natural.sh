#!/bin/sh
# Rebuild the natural (ungraded) palettes shipped in wbcgrade/color/data/natural.npz,
# the content model of look extraction (wbcgrade/color/look/set_extraction.py).
# Run from the repository root:
#   python presets/gather_natural.py CORPUS      # photos of presets/natural_corpus.csv
#   sh presets/build_natural.sh CORPUS/photos
# Every photo, its author, licence and source package is listed in
# presets/natural_corpus.csv and wbcgrade/color/data/NATURAL.md.
set -e
folder=${1:?usage: sh presets/build_natural.sh PHOTO_FOLDER}
python -m wbcgrade preset build "$folder" -o wbcgrade/color/data/natural.npz --bins 32 --no-cache \
    --overwrite --compact --description "palettes of ungraded photos (content model of look extraction)"
