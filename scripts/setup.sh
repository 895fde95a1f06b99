#!/bin/sh
# Set up o3d-rpointhop in ./.venv: the system libraries Open3D's wheel links against
# (on Debian/Ubuntu, installed with apt-get when missing), a virtual environment and the
# package. Safe to run again.
#
#   sh scripts/setup.sh          what the library and the demo need (the package, and
#                                matplotlib for the demo's picture)
#   sh scripts/setup.sh --test   everything the tests use as well: the test, plot,
#                                distributed, survey-file, HDF5, viewer and benchmark-peer
#                                extras, and Debian's chromium for the browser tests
set -eu
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
MODE=core
case "${1:-}" in
    "") ;;
    --test) MODE=test ;;
    *) echo "usage: sh scripts/setup.sh [--test]" >&2; exit 2 ;;
esac

missing=""
for lib in libusb-1.0.so.0 libGL.so.1 libEGL.so.1 libgomp.so.1 libX11.so.6; do
    if ! (ldconfig -p 2>/dev/null || /sbin/ldconfig -p 2>/dev/null) | grep -q "$lib"; then
        missing="yes"
    fi
done
if ! "$PYTHON" -c "import ensurepip, venv" >/dev/null 2>&1; then
    missing="yes"
fi
if [ -n "$missing" ] && command -v apt-get >/dev/null 2>&1; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    echo "setup: installing system libraries for Open3D (libusb-1.0-0, libgl1, libegl1, libgomp1)"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq \
        libusb-1.0-0 libgl1 libegl1 libgomp1 libx11-6 python3-venv >/dev/null
fi

# The viewer's browser tests drive Debian's Chromium (playwright, no browser download).
if [ "$MODE" = test ] && ! command -v chromium >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    echo "setup: installing chromium for the viewer's browser tests"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv"
    "$PYTHON" -m venv .venv
fi
# Reinstall only when pyproject.toml changed since the last successful install (a test
# install serves the core set-up too: it is a superset).
stamp=.venv/.o3d-rpointhop-installed
sum=$(cksum pyproject.toml | cut -d' ' -f1)
have=$(cat "$stamp" 2>/dev/null || true)
if [ "$MODE" = test ]; then
    want="$sum test"
    extras="[test,plot,distributed,las,e57,h5,view,peers]"
    what="o3d-rpointhop and its test, plot, distributed, survey-file, HDF5, viewer and benchmark-peer extras"
else
    want="$sum core"
    extras="[plot]"
    what="o3d-rpointhop (with matplotlib, for the demo's picture)"
fi
if [ "$have" != "$want" ] && [ "$have" != "$sum test" ]; then
    echo "setup: installing $what"
    # pip's notices go to a log, shown only if the install fails.
    log=.venv/pip-install.log
    if ! { .venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip &&
        .venv/bin/python -m pip install -q --disable-pip-version-check \
            -e ".$extras"; } > "$log" 2>&1; then
        cat "$log" >&2
        echo "setup: pip install failed (log above, also in $log)" >&2
        exit 1
    fi
    # The compiled kernels compile on first use (10-20 s once per environment, then
    # loaded from numba's cache): compile them now, so that the first command is warm.
    echo "setup: compiling the kernels (once per environment)"
    if ! .venv/bin/python -c "
from o3d_rpointhop import RPointHopTransformer, register
from o3d_rpointhop.datasets import make_object
cloud = make_object(1500)
register(cloud + 0.1, cloud)
register(cloud + 0.1, cloud, global_method='consensus')
RPointHopTransformer.pretrained('scene').transform(cloud, viewpoints='origin')
" > "$log" 2>&1; then
        cat "$log" >&2
        echo "setup: compiling the kernels failed (log above)" >&2
        exit 1
    fi
    echo "$want" > "$stamp"
fi
if [ "$MODE" = test ]; then
    echo "setup: ready (.venv/bin/o3d-rpointhop, .venv/bin/python -m pytest)"
else
    echo "setup: ready (.venv/bin/o3d-rpointhop; 'sh scripts/setup.sh --test' adds what the tests use)"
fi
