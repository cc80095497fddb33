#!/usr/bin/env sh
# Set up the real readers the tests check iblbake's files with: Node.js (Debian's nodejs and
# npm) with the npm packages of tests/node/package.json, pinned by its package-lock.json
# (ktx-parse, @khronosgroup/gltf-viewer for its libktx, gltf-validator, Babylon.js and
# puppeteer-core), into tests/node/node_modules; Debian's chromium, in which Babylon.js renders
# the glTF lights (headless, WebGL2 on SwiftShader); and glslangValidator (Debian's
# glslang-tools) for the GLSL export.
# What is missing is installed with apt-get.
set -u
DIR="${1:-tests/node}"
SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"
need=""
{ command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1; } || need="nodejs npm"
command -v glslangValidator >/dev/null 2>&1 || need="$need glslang-tools"
[ -x /usr/bin/chromium ] || need="$need chromium"
if [ -n "$need" ]; then
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "ensure_readers: missing $need and no apt-get; install Node.js 18 or later, glslang and Chromium" >&2
        exit 1
    fi
    echo "ensure_readers: installing Debian's $need" >&2
    $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $need >/dev/null || exit 1
fi
[ -f "$DIR/node_modules/.iblbake-complete" ] && [ "$DIR/node_modules/.iblbake-complete" -nt "$DIR/package-lock.json" ] && exit 0
(cd "$DIR" && npm ci --no-audit --no-fund --loglevel=error) || { echo "ensure_readers: npm ci failed in $DIR" >&2; exit 1; }
# the Sample Viewer's libktx.js is an ES-module package's file: a .cjs copy lets Node require it
cp "$DIR/node_modules/@khronosgroup/gltf-viewer/dist/libs/libktx.js" "$DIR/node_modules/.libktx.cjs" || exit 1
touch "$DIR/node_modules/.iblbake-complete"
