#!/bin/sh
# Build the Crazyflie firmware's software-in-the-loop executable `cf2` (GPL-3.0, CrazySim's
# sitl-release) into $OUT (default .sitl/) from the pinned snapshot in $SITL_SRC (default
# ../shared/sitl). It runs as its own process: nothing of it enters the Python package.
# A second call costs nothing while $OUT/cf2 is there and built from the same snapshot and patches
# ($OUT/cf2.key); a changed snapshot or patch rebuilds it.
# Patches: the snapshot's stabilizer-ticktype.patch (start-up hang), then tools/sitl-*.patch
# (sitl-socketlink-nodrop.patch: the socket link dropped ~5 % of cflib's requests, which hangs
# cflib's UDP driver, as it never resends; sitl-socketlink-loopback.patch: the firmware's socket
# binds 127.0.0.1, not every interface; sitl-kalman-pose-residual.patch: upstream's fix #1531 of
# the Kalman filter's external-pose attitude residual, which diverged beyond |yaw| = 90 deg;
# sitl-idle-sleep.patch: an idle hook that sleeps a tick, as the idle task spun half a core).
set -eu
HERE=$(cd "$(dirname "$0")" && pwd)
SRC=${SITL_SRC:-../shared/sitl}
OUT=${SITL_OUT:-.sitl}
JOBS=${SITL_JOBS:-2}
BIN="$OUT/cf2"
# The cache key: the snapshot (size and time, not read) and every patch (read: they are small).
key() {
    stat -c '%s %Y' "$SRC/crazyflie-firmware-sitl.tar.xz" 2>/dev/null || echo none
    cat "$SRC/stabilizer-ticktype.patch" "$HERE"/sitl-*.patch "$HERE/build_sitl.sh" 2>/dev/null \
        | cksum
}
if [ "${1:-}" = "--key" ]; then  # print the cache key (for the tests)
    key
    exit 0
fi
if [ -x "$BIN" ] && [ "$(key)" = "$(cat "$BIN.key" 2>/dev/null)" ]; then
    exit 0
fi
need() {  # need TOOL DEBIAN-PACKAGE
    command -v "$1" >/dev/null 2>&1 || { echo "make sitl: '$1' not found; install it: sudo apt-get install $2" >&2; exit 2; }
}
need gcc gcc
need cmake cmake
need make make
need git git
need patch patch
need tar tar
need xz xz-utils
TARBALL="$SRC/crazyflie-firmware-sitl.tar.xz"
PATCH="$SRC/stabilizer-ticktype.patch"
if [ ! -r "$TARBALL" ] || [ ! -r "$PATCH" ]; then
    echo "make sitl: no firmware snapshot at $SRC (set SITL_SRC; see docs/sitl.md to fetch the pinned upstream sources)" >&2
    exit 2
fi
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
SRC=$(cd "$SRC" && pwd)
BIN="$OUT/cf2"
WORK="$OUT/build"
rm -rf "$WORK"
mkdir -p "$WORK/shim"
# The firmware's cmake calls `python`; Debian only has python3 unless python-is-python3 is installed.
if ! command -v python >/dev/null 2>&1; then
    need python3 python3
    ln -s "$(command -v python3)" "$WORK/shim/python"
fi
PATH="$WORK/shim:$PATH"
export PATH
LOG="$OUT/build.log"
echo "make sitl: building the firmware (log: $LOG)"
(
    set -e
    tar xJf "$SRC/crazyflie-firmware-sitl.tar.xz" -C "$WORK"
    cd "$WORK/crazyflie-firmware"
    patch -p1 < "$SRC/stabilizer-ticktype.patch"
    for extra in "$HERE"/sitl-*.patch; do patch -p1 < "$extra"; done
    # version.c is generated from `git rev-parse HEAD` and `git describe --tags`: tagged with
    # the snapshot's commit (shared/sitl/README.md), the firmware reports that version (a
    # session's `firmware`), not "NA"
    git init -q && git add -A && git -c user.name=sitl -c user.email=sitl@localhost commit -qm snapshot
    git tag sitl.6a4d2d00+patches  # no "-": versionTemplate.py splits the tag at them
    mkdir -p sitl_make/build && cd sitl_make/build
    cmake .. && make -j"$JOBS" cf2
) > "$LOG" 2>&1 || { echo "make sitl: the firmware build failed; see $LOG" >&2; exit 1; }
cp "$WORK/crazyflie-firmware/sitl_make/build/cf2" "$BIN.tmp"
mv "$BIN.tmp" "$BIN"
key > "$BIN.key"
rm -rf "$WORK"
echo "make sitl: built $BIN"
