#!/usr/bin/env bash
# Create (or update) the virtual environment .venv with everything cone_feeder_sim needs:
# the ROS 2 Jazzy Python wheels from PyPI, the run-time dependencies, the test tools, and
# the package itself (editable). Safe to run again.
# The versions are those the test suite last passed with (requirements/constraints.txt);
# CONSTRAINTS=none takes the newest the floors admit instead (scripts/refresh_constraints.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
CONSTRAINTS="${CONSTRAINTS:-requirements/constraints.txt}"
if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
PIN=()
if [ "$CONSTRAINTS" != none ]; then
  PIN=(-c "$CONSTRAINTS")
fi
.venv/bin/python -m pip install --disable-pip-version-check -q "${PIN[@]}" -r requirements/test.txt
.venv/bin/python -m pip install --disable-pip-version-check -q --no-deps -e .
# Byte-compile the package, as a regular pip install or a colcon build does (an editable
# install leaves that to the first import, and not at all under PYTHONDONTWRITEBYTECODE):
# every process the node and the tests start then imports it without compiling.
.venv/bin/python -m compileall -q cone_feeder_sim > /dev/null
# Compile the integration kernel into numba's cache now, so that no start has to (about
# 10-60 s once; later starts load it in well under a second).
.venv/bin/cone-feeder-sim compile
