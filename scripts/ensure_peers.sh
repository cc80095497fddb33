#!/usr/bin/env sh
# Set up the peer renderer the path-traced reference is tested against (tests/test_paths.py):
# Mitsuba 3 from PyPI in the given Python's environment, and Debian's libllvm19 for its CPU
# variant (llvm_ad_rgb, through DRJIT_LIBLLVM_PATH). What is missing is installed.
set -u
PY="${1:-.venv/bin/python}"
SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"
LLVM=/usr/lib/x86_64-linux-gnu/libLLVM-19.so
if [ ! -e "$LLVM" ]; then
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "ensure_peers: $LLVM missing and no apt-get; install LLVM 19's shared library" >&2
        exit 1
    fi
    echo "ensure_peers: installing Debian's libllvm19" >&2
    $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null || exit 1
fi
"$PY" -c "import mitsuba" 2>/dev/null && exit 0
echo "ensure_peers: installing mitsuba" >&2
"$PY" -m pip install -q mitsuba || { echo "ensure_peers: pip install mitsuba failed" >&2; exit 1; }
