#!/usr/bin/env bash
# The canary (issue 4): 5 expert demos of ONE grid_id scene, train the CPU preset <= 15 min, then 5
# closed-loop runs on that scene and the target-sensitivity check on the same checkpoint.
# TARGETS=2 designates the scene's target and its grid neighbour in turn (same first image, only the
# bbox tells them apart), in the demos and in the runs.
# Run from the repository root; sources scripts/setup.sh (creates .venv when missing).
set -euo pipefail
source scripts/setup.sh
SEED=${SEED:-0}
OUT=${OUT:-outputs/canary}
TARGETS=${TARGETS:-1}
STEPS=${STEPS:-1500}  # 12-14 min at 1.8-2.1 steps/s (batch 32, bf16 autocast) on 2 cores
# The cpu preset as it is (mask centroid on). On 2026-12-01 it picked 5/5 executing 8 and 16 steps per
# chunk and 0/5 executing 12 (the preset's value: a re-plan lands at the grasp), so all three run.
# MASK_CENTROID=false trains without the centroid: 5/5 at 12 and 16, but then the one-scene policy
# does not read the bbox at all (README, "The canary").
MASK_CENTROID=${MASK_CENTROID:-true}
EXEC_STEPS=${EXEC_STEPS:-8 12 16}
[ -d "$OUT/data" ] || python -m lerobot_bboxpick.apps.canary record --root "$OUT/data" --seed "$SEED" \
  --episodes 5 --targets "$TARGETS"
rm -rf "$OUT/train"
OMP_NUM_THREADS=2 lerobot-train --policy.type=bbox_diffusion --policy.device=cpu \
  --policy.use_amp=true --policy.mask_centroid="$MASK_CENTROID" --policy.scheduler_warmup_steps=100 \
  --dataset.repo_id=local/canary --dataset.root="$OUT/data" --output_dir="$OUT/train" \
  --steps="$STEPS" --batch_size=32 --num_workers=1 --save_freq=500 --log_freq=50 --wandb.enable=false
CKPT="$OUT/train/checkpoints/last/pretrained_model"
for n in $EXEC_STEPS; do
  echo "[canary] executing $n of 16 steps per chunk"
  python -m lerobot_bboxpick.apps.canary evaluate --policy "$CKPT" --seed "$SEED" --runs 5 --targets "$TARGETS" \
    --n-action-steps "$n" --video-dir "$OUT/videos/exec$n"
done
python -m lerobot_bboxpick.apps.canary sensitivity --policy "$CKPT" --seed "$SEED"
