#!/usr/bin/env sh
# Fetch real (and deliberately malformed) meshes from Debian's assimp-testmodels for the loader
# fuzz tests: OBJ, PLY, STL, OFF, and the glTF 2 files with out-of-range indices, infinities,
# schema failures, wrong types, missing buffers and Draco compression.
set -eu
DEST="${1:-tests/data/assimp}"
[ -s "$DEST/.complete" ] && exit 0
command -v apt-get >/dev/null 2>&1 || { echo "fetch_testmodels: needs Debian's apt-get (or extract assimp-testmodels' models/ into $DEST)" >&2; exit 1; }
mkdir -p "$DEST"
DEST=$(cd "$DEST" && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
cd "$TMP"
if ! apt-get download assimp-testmodels >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    apt-get download assimp-testmodels >/dev/null
fi
dpkg -x assimp-testmodels_*.deb x
M=x/usr/share/assimp/models
for d in OBJ PLY STL OFF invalid glTF2/IndexOutOfRange glTF2/BoxWithInfinites-glTF-Binary \
         glTF2/SchemaFailures glTF2/wrongTypes glTF2/MissingBin glTF2/IncorrectVertexArrays \
         glTF2/RecursiveNodes glTF2/draco glTF2/BoxTextured-glTF-Binary glTF2/TestNoRootNode; do
    mkdir -p "$DEST/$d"
    cp -R "$M/$d/." "$DEST/$d/"
done
echo "assimp-testmodels $(ls x/usr/share/doc/assimp-testmodels >/dev/null 2>&1 && dpkg-deb -f assimp-testmodels_*.deb Version)" > "$DEST/.complete"
echo "fetch_testmodels: meshes in $DEST" >&2
