#!/usr/bin/env sh
# deb_extract.sh PACKAGE DIR: download a Debian package (without installing it) and unpack its
# files under DIR. Shared by fetch_panoramas.sh and fetch_testmodels.sh.
set -eu
PKG="$1"; DIR="$2"
command -v apt-get >/dev/null 2>&1 || { echo "deb_extract: needs Debian's apt-get to fetch $PKG" >&2; exit 1; }
mkdir -p "$DIR"
cd "$DIR"
if ! apt-get download "$PKG" >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    apt-get download "$PKG" >/dev/null
fi
dpkg -x "$PKG"_*.deb x
