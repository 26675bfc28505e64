#!/usr/bin/env bash
# Create .venv and install muvsim with its pinned dependencies (SUMO comes from PyPI).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if ! "$PY" -c 'import sys, venv, ensurepip; assert sys.version_info >= (3, 11)' 2>/dev/null; then
    # Debian/Ubuntu machines without venv support or an old Python: install it.
    if command -v apt-get >/dev/null 2>&1; then
        apt-get update -qq && apt-get install -y -qq python3 python3-venv python3-pip >/dev/null
        PY=python3
    fi
fi
# SUMO (sumo, netgenerate, duarouter, libsumo) comes from the eclipse-sumo / libsumo wheels.
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
# On a slimmer image SUMO's binaries may miss X11/GL/expat client libraries: install them.
SUMO_BIN=$(.venv/bin/python -c 'import os, sumo; print(os.path.join(sumo.SUMO_HOME, "bin", "sumo"))')
if ldd "$SUMO_BIN" 2>/dev/null | grep -q "not found" && command -v apt-get >/dev/null 2>&1; then
    apt-get update -qq && apt-get install -y -qq libx11-6 libxext6 libxrender1 libgl1 libexpat1 \
        libxcb1 libbsd0 zlib1g >/dev/null
fi
