#!/usr/bin/env bash
# The canary (issue 4): 5 expert demos of ONE grid_id scene, train the CPU preset <= 15 min, then 5
# closed-loop runs on that scene. Run from the repository root after `bash scripts/test.sh` set up .venv.
set -euo pipefail
source scripts/setup.sh
SEED=${SEED:-0}
OUT=${OUT:-outputs/canary}
STEPS=${STEPS:-1000}  # ~14.5 min at ~1.15 steps/s (batch 32) on 2 cores
[ -d "$OUT/data" ] || python -m lerobot_bboxpick.canary record --root "$OUT/data" --seed "$SEED" --episodes 5
rm -rf "$OUT/train"
OMP_NUM_THREADS=2 lerobot-train --policy.type=bbox_diffusion --policy.preset=cpu --policy.device=cpu \
  --policy.scheduler_warmup_steps=100 --policy.n_action_steps=12 \
  --dataset.repo_id=local/canary --dataset.root="$OUT/data" --output_dir="$OUT/train" \
  --steps="$STEPS" --batch_size=32 --num_workers=1 --save_freq=500 --log_freq=50 --wandb.enable=false
python -m lerobot_bboxpick.canary evaluate --policy "$OUT/train/checkpoints/last/pretrained_model" \
  --seed "$SEED" --runs 5 --video-dir "$OUT/videos"
