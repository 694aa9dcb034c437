#!/bin/sh
# tools/scripts/deps.sh (`make deps`, and the set-up step of `make demo` / `make test`) against
# fake dpkg-query, id, sudo and apt-get on PATH, so nothing is installed: with every package of
# tools/scripts/packages.txt present it prints nothing and calls no apt-get; with some missing,
# as root it installs exactly those (after an update, waiting for the apt lock) and says so;
# through `sudo -n` likewise; with neither it prints the exact apt-get line and fails (also run
# for real as the user nobody when the test runs as root).
NAME=deps
. "$(dirname "$0")/lib_cli.sh"
F="$T/fake"
mkdir -p "$F"
LIST=$(sed 's/#.*//' tools/scripts/packages.txt | tr -s ' \t\n' '   ')
# dpkg-query -W -f=FORMAT PKG...: "PKG install ok installed" for each PKG not in $FAKE_MISSING
cat > "$F/dpkg-query" <<'FAKE'
#!/bin/sh
shift 2
for p in "$@"; do
    case " $FAKE_MISSING " in *" $p "*) ;; *) echo "$p install ok installed" ;; esac
done
FAKE
cat > "$F/id" <<'FAKE'
#!/bin/sh
echo "$FAKE_UID"
FAKE
cat > "$F/apt-get" <<'FAKE'
#!/bin/sh
echo "apt-get $* (uid $FAKE_UID${FAKE_VIA_SUDO:+, via sudo})" >> "$FAKE_LOG"
FAKE
# sudo -n CMD...: runs CMD when FAKE_SUDO=yes; fails as sudo does without a password otherwise
cat > "$F/sudo" <<'FAKE'
#!/bin/sh
[ "$FAKE_SUDO" = yes ] || { echo "sudo: a password is required" >&2; exit 1; }
[ "$1" = -n ] || { echo "sudo without -n would prompt" >&2; exit 1; }
shift
FAKE_VIA_SUDO=1 exec "$@"
FAKE
chmod +x "$F"/*
# deps MISSING UID SUDO: runs deps.sh with those fakes; $T/out, $T/err, $T/apt.log
deps() {
    rm -f "$T/apt.log"
    env PATH="$F:$PATH" FAKE_MISSING="$1" FAKE_UID="$2" FAKE_SUDO="$3" FAKE_LOG="$T/apt.log" \
        sh tools/scripts/deps.sh > "$T/out" 2> "$T/err"
    echo $?
}
check "the list has the packages the issue names" sh -c 'for p in zip curl libmicrohttpd-dev libcurl4-openssl-dev libopenimageio-dev; do echo " $1 " | grep -q " $p " || exit 1; done' - "$LIST"

check "all present: exit 0" [ "$(deps "" 1000 no)" = 0 ]
check "all present: prints nothing" [ ! -s "$T/out" ] && [ ! -s "$T/err" ]
check "all present: no apt-get" [ ! -e "$T/apt.log" ]

check "two missing, as root: exit 0" [ "$(deps "zip libcurl4-openssl-dev" 0 no)" = 0 ]
check "says what it installs" grep -q "^deps: installing the missing Debian packages: zip libcurl4-openssl-dev$" "$T/out"
check "updates first, then installs only those" sh -c "sed -n 1p '$T/apt.log' | grep -q ' update ' &&
    sed -n 2p '$T/apt.log' | grep -q ' install -y .*--no-install-recommends zip libcurl4-openssl-dev (uid 0)$' &&
    [ \$(wc -l < '$T/apt.log') = 2 ]"
check "waits for the apt lock" grep -q -- "-o DPkg::Lock::Timeout=[1-9]" "$T/apt.log"

check "missing, user with sudo -n: exit 0" [ "$(deps "zip" 1000 yes)" = 0 ]
check "installs through sudo -n" grep -q "install .* zip (uid 1000, via sudo)$" "$T/apt.log"

check "missing, user without sudo: exit 1" [ "$(deps "zip curl" 1000 no)" = 1 ]
check "names what is missing" grep -q "missing Debian packages: zip curl$" "$T/err"
check "prints the exact apt-get line" grep -q "^    apt-get update && apt-get install -y --no-install-recommends zip curl$" "$T/err"
check "and installs nothing" [ ! -e "$T/apt.log" ]

# a real user without root (as root, which CI is: nobody through setpriv), only dpkg-query faked
if [ "$(id -u)" = 0 ] && command -v setpriv > /dev/null 2>&1; then
    mkdir -p "$T/dpkg_only" && cp "$F/dpkg-query" "$T/dpkg_only/" && chmod -R a+rX "$T"
    rc=$(setpriv --reuid=65534 --regid=65534 --clear-groups env PATH="$T/dpkg_only:$PATH" FAKE_MISSING=zip \
        sh tools/scripts/deps.sh > "$T/out" 2> "$T/err"; echo $?)
    check "nobody, zip missing: exit 1" [ "$rc" = 1 ]
    check "nobody: the exact apt-get line" grep -q "^    apt-get update && apt-get install -y --no-install-recommends zip$" "$T/err"
fi
exit $fail
