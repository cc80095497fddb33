#!/usr/bin/env sh
# Fetch the eight CC0 1024x512 EXR panoramas that Debian's blender-data package ships
# (city courtyard forest interior night studio sunrise sunset) without installing Blender.
set -eu
DEST="${1:-examples/panoramas}"
NAMES="city courtyard forest interior night studio sunrise sunset"
missing=0
for n in $NAMES; do [ -s "$DEST/$n.exr" ] || missing=1; done
[ "$missing" = 0 ] && exit 0
mkdir -p "$DEST"
DEST=$(cd "$DEST" && pwd)
HERE=$(cd "$(dirname "$0")" && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
sh "$HERE/deb_extract.sh" blender-data "$TMP" || { echo "fetch_panoramas: or copy the EXRs of blender-data's studiolights/world into $DEST" >&2; exit 1; }
cd "$TMP"
for n in $NAMES; do
    cp "x/usr/share/blender/datafiles/studiolights/world/$n.exr" "$DEST/.$n.exr.tmp"
    mv "$DEST/.$n.exr.tmp" "$DEST/$n.exr"
done
echo "fetch_panoramas: 8 panoramas in $DEST" >&2
