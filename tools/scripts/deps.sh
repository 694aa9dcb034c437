#!/bin/sh
# Installs the Debian 12 packages of tools/scripts/packages.txt that are missing, without
# questions; prints nothing when none is (one dpkg-query call, no apt-get update). `make deps`
# runs it, and so do `make demo` and `make test` before they build. As root, or through
# `sudo -n` (never a password prompt); otherwise it prints the exact apt-get line to run and
# fails. apt-get waits up to 10 minutes for another apt holding the lock. Works without make:
# sh tools/scripts/deps.sh. Not Debian (no dpkg-query): says so and leaves the packages alone.
# Optional extras, not installed here: clang (CC=clang make), libopenblas-dev (make bench).
set -eu
LIST="$(dirname "$0")/packages.txt"
PACKAGES=$(sed 's/#.*//' "$LIST" | tr -s ' \t\n' '   ')

if ! command -v dpkg-query > /dev/null 2>&1; then
    echo "deps: no dpkg-query (not Debian): install the equivalents of $LIST yourself" >&2
    exit 0
fi

# The packages of the list that are not installed (dpkg-query prints nothing for unknown ones).
missing=""
installed=$(dpkg-query -W -f='${Package} ${Status}\n' $PACKAGES 2> /dev/null | awk '$NF == "installed" {print $1}')
for p in $PACKAGES; do
    printf '%s\n' "$installed" | grep -qx "$p" || missing="$missing $p"
done
missing=${missing# }
[ -n "$missing" ] || exit 0

APT="env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600"
INSTALL="apt-get install -y --no-install-recommends $missing"
if [ "$(id -u)" -eq 0 ]; then
    SUDO=""
elif command -v sudo > /dev/null 2>&1 && sudo -n true 2> /dev/null; then
    SUDO="sudo -n"
else
    echo "deps: missing Debian packages: $missing" >&2
    echo "deps: installing them needs root (or sudo without a password prompt); as root, run:" >&2
    echo "    apt-get update && $INSTALL" >&2
    exit 1
fi
echo "deps: installing the missing Debian packages: $missing"
$SUDO $APT update -qq
$SUDO $APT install -y -qq --no-install-recommends $missing
