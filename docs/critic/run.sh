#!/usr/bin/env bash
# The first critic study (issue 15): rollouts of the main job's quick checkpoint (failures kept) merged with
# its 30 expert demos, an IQL critic on the policy's frozen encoder, and the verification report.
# Run from the repository root after `bash scripts/main.sh` (which writes outputs/main/quick).
set -euo pipefail
source scripts/setup.sh
CKPT=outputs/main/quick/train/checkpoints/last/pretrained_model
bboxpick-rollouts --policy_path=$CKPT --repo_id=local/rl_quick --root=outputs/rl_quick/data \
    --episodes=3 --max_steps=200 --workers=2 --merge_with=outputs/main/quick/data \
    --stats_png=docs/critic/dataset_stats.png
bboxpick-train-critic --dataset.repo_id=local/rl_quick --dataset.root=outputs/rl_quick/data \
    --policy_path=$CKPT --output_dir=outputs/rl_quick/critic --overwrite=true
bboxpick-verify-critic --critic_path=outputs/rl_quick/critic/checkpoints/last/pretrained_model \
    --dataset.repo_id=local/rl_quick --dataset.root=outputs/rl_quick/data --out_dir=docs/critic/report
