#!/usr/bin/env bash
# The main job on the embedded default: set up, then collect a small expert dataset in the simulator,
# train the bbox_diffusion CPU preset briefly with lerobot-train, and evaluate it beside the expert
# on all six settings with bboxpick-suite (about 15 minutes on 2 cores; resumes if interrupted).
# `bash scripts/main.sh --profile full` runs the full-size version (the 90-minute recipe, 6 x 30 suite).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
lerobot_bboxpick run "$@"
