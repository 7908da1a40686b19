#!/usr/bin/env bash
# The CPU recipe of issue 5: a bbox_diffusion policy trained within the 90-minute budget (43 min with bf16
# autocast, 76 min without) on this 2-core machine,
# then the full matched-scene suite (6 settings x 30 held-out episodes, with the expert as upper bound).
# Run from the repository root. Every stage resumes when re-run; nothing else should use the CPU while it
# trains (two torch jobs on 2 cores slow each other down 5-10x, not 2x).
#
#   1. bboxpick-collect --repo_id=local/lego_pick_full --root=outputs/main/full/data \
#        --settings=grid_id,identical_4 --episodes=200 --workers=2 --resume=true       (~9 min)
#   2. lerobot-train --policy.type=bbox_diffusion --policy.bbox_mode=mask \
#        --policy.mask_centroid=true --policy.device=cpu --policy.scheduler_warmup_steps=300 \
#        --policy.n_action_steps=12 --policy.use_amp=true --dataset.repo_id=local/lego_pick_full \
#        --dataset.root=outputs/main/full/data --output_dir=outputs/main/full/train \
#        --steps=5000 --batch_size=32 --num_workers=1 --save_freq=1000 --log_freq=50 --wandb.enable=false
#                                                                                        (~43 min)
#   3. bboxpick-suite --policies=expert,bbox_diffusion=outputs/main/full/train/checkpoints/last/pretrained_model \
#        --episodes=30 --workers=2 --out_dir=outputs/main/full/suite                        (~6 min)
# BBOX_MODE=none trains and evaluates the no-prompt ablation the same way, on the same demos, into
# outputs/main/full/{train,suite}_none (its lerobot-train call has --policy.bbox_mode=none
# --policy.mask_centroid=false and the output folder as the only differences).
# AMP=0 trains in float32 (--policy.use_amp=false): for CPUs without native bf16, where autocast is slower.
set -euo pipefail
source scripts/setup.sh
amp_flag="--amp"; [ "${AMP:-1}" = "0" ] && amp_flag="--no-amp"
lerobot_bboxpick run --profile full --bbox-mode "${BBOX_MODE:-mask}" "$amp_flag"
