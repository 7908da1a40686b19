#!/usr/bin/env bash
# The main job on the embedded default: set up, then roll the scripted expert out in all six
# lego_pick settings and write videos, a contact sheet and an outcome table to outputs/demo.
# Extra arguments go to `lerobot_bboxpick demo` (e.g. --episodes 5).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
lerobot_bboxpick demo --out-dir outputs/demo "$@"
