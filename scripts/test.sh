#!/usr/bin/env bash
# Set up, then run the whole test suite (real MuJoCo rendering, LeRobot CLIs in subprocesses).
# Exits non-zero when any test fails; lists the 25 slowest tests. Extra arguments go to pytest.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
python -m pytest -q --durations=25 tests "$@"
