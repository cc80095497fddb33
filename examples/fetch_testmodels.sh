#!/usr/bin/env sh
# Fetch real (and deliberately malformed) meshes from Debian's assimp-testmodels for the loader
# fuzz tests: OBJ, PLY, STL, OFF, and the glTF 2 files with out-of-range indices, infinities,
# schema failures, wrong types, missing buffers and Draco compression.
set -eu
DEST="${1:-tests/data/assimp}"
[ -s "$DEST/.complete" ] && exit 0
mkdir -p "$DEST"
DEST=$(cd "$DEST" && pwd)
HERE=$(cd "$(dirname "$0")" && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
sh "$HERE/deb_extract.sh" assimp-testmodels "$TMP" || { echo "fetch_testmodels: or extract assimp-testmodels' models/ into $DEST" >&2; exit 1; }
cd "$TMP"
M=x/usr/share/assimp/models
for d in OBJ PLY STL OFF invalid glTF2/IndexOutOfRange glTF2/BoxWithInfinites-glTF-Binary \
         glTF2/SchemaFailures glTF2/wrongTypes glTF2/MissingBin glTF2/IncorrectVertexArrays \
         glTF2/RecursiveNodes glTF2/draco glTF2/BoxTextured-glTF-Binary glTF2/TestNoRootNode; do
    mkdir -p "$DEST/$d"
    cp -R "$M/$d/." "$DEST/$d/"
done
echo "assimp-testmodels $(dpkg-deb -f assimp-testmodels_*.deb Version)" > "$DEST/.complete"
echo "fetch_testmodels: meshes in $DEST" >&2
