#!/usr/bin/env bash
# Refresh requirements/constraints.txt: build .venv anew with the newest versions the
# requirements admit, run the README's test command in it, and pin what it installed only
# when every test passed. Run it on purpose (a new numpy, numba, rosbags...), then commit
# the file with the suite's result. Set-up takes a few minutes; the suite about four.
set -euo pipefail
cd "$(dirname "$0")/.."
rm -rf .venv
CONSTRAINTS=none bash scripts/setup_venv.sh
.venv/bin/python -m pytest -q -n auto --dist loadfile test
.venv/bin/python scripts/freeze_constraints.py > requirements/constraints.txt
echo "requirements/constraints.txt: $(grep -vc '^#' requirements/constraints.txt) pins"
