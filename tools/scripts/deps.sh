#!/bin/sh
# `make deps`: installs, without questions, the Debian 12 packages that building matex and
# running `make demo` and `make test` need (compilers and make, pkg-config, the mesh and image
# I/O libraries). As root, or through sudo otherwise. Works without make: sh tools/scripts/deps.sh.
# Optional extras, not installed here: clang (CC=clang make), libopenblas-dev (make bench).
set -eu
PACKAGES="build-essential pkg-config libopenmesh-dev libopenimageio-dev libopenexr-dev libimath-dev zlib1g-dev libmicrohttpd-dev libcurl4-openssl-dev curl"
if [ "$(id -u)" -eq 0 ]; then
    SUDO=""
elif command -v sudo > /dev/null; then
    SUDO="sudo"
else
    echo "deps: run as root, or install sudo: apt-get install needs root" >&2
    exit 1
fi
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get update
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $PACKAGES
