#!/usr/bin/env sh
# Make sure a working OpenCL device exists (one that builds and runs a probe kernel).
# On Debian/Ubuntu, installs PoCL's CPU driver (pocl-opencl-icd) with apt-get when none works.
set -u
IBLBAKE="${1:-.venv/bin/iblbake}"
if "$IBLBAKE" devices -q; then exit 0; fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "ensure_opencl: no working OpenCL device and no apt-get; install an OpenCL driver (PoCL or your GPU's)" >&2
    exit 1
fi
SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"
echo "ensure_opencl: no working OpenCL device; installing Debian's pocl-opencl-icd" >&2
$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd ocl-icd-libopencl1 >/dev/null || exit 1
"$IBLBAKE" devices
