#!/usr/bin/env sh
# Set up the real readers the tests check iblbake's files with (tests/node/package.json, pinned
# by its package-lock.json): Node.js (Debian's nodejs and npm, installed with apt-get when
# missing) and the npm packages ktx-parse, @khronosgroup/gltf-viewer (its libktx) and
# gltf-validator, into tests/node/node_modules.
set -u
DIR="${1:-tests/node}"
[ -f "$DIR/node_modules/.iblbake-complete" ] && [ "$DIR/node_modules/.iblbake-complete" -nt "$DIR/package-lock.json" ] && exit 0
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "ensure_node: no node/npm and no apt-get; install Node.js 18 or later" >&2
        exit 1
    fi
    SUDO=""
    [ "$(id -u)" = 0 ] || SUDO="sudo"
    echo "ensure_node: installing Debian's nodejs and npm" >&2
    $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq nodejs npm >/dev/null || exit 1
fi
(cd "$DIR" && npm ci --no-audit --no-fund --loglevel=error) || { echo "ensure_node: npm ci failed in $DIR" >&2; exit 1; }
touch "$DIR/node_modules/.iblbake-complete"
