#!/usr/bin/env bash
# The CPU recipe: a bbox_diffusion policy trained within a 90-minute budget on a 2-core CPU, then the
# full matched-scene suite (6 settings x 30 test scenes, the expert as upper bound). Results and the
# exact figures: docs/results.md. Run from the repository root. Every stage resumes when re-run; nothing
# else should use the CPU while it trains (two torch jobs on 2 cores slow each other down 5-10x).
#
#   1. bboxpick-collect --repo_id=local/lego_pick_full --root=outputs/main/full/data \
#        --settings=grid_id,identical_4 --episodes=200 --workers=2 --resume=true   (training seeds 0-199)
#   2. lerobot-train --policy.type=bbox_diffusion --policy.bbox_mode=mask --policy.mask_centroid=true \
#        --policy.device=cpu --policy.scheduler_warmup_steps=300 --policy.n_action_steps=12 \
#        --policy.use_amp=<true where the CPU has native bf16, else false> \
#        --dataset.repo_id=local/lego_pick_full --dataset.root=outputs/main/full/data \
#        --output_dir=outputs/main/full/train --steps=5000 --batch_size=32 --num_workers=1 \
#        --save_freq=1000 --log_freq=10 --wandb.enable=false          (160,000 samples; ETA printed)
#   3. bboxpick-suite --policies=expert,bbox_diffusion=outputs/main/full/train/checkpoints/last/pretrained_model \
#        --episodes=30 --workers=2 --out_dir=outputs/main/full/suite                 (test seeds 10000+)
# BBOX_MODE=none trains and evaluates the no-prompt ablation the same way, on the same demos, into
# outputs/main/full/{train,suite}_none. AMP=1 / AMP=0 force bf16 autocast / float32 (default: chosen
# from the CPU, lerobot_bboxpick/precision.py).
set -euo pipefail
source scripts/setup.sh
amp_flag=()
case "${AMP:-}" in
  1) amp_flag=(--amp) ;;
  0) amp_flag=(--no-amp) ;;
  "") ;;
  *) echo "AMP=${AMP} must be 1, 0 or unset" >&2; exit 2 ;;
esac
lerobot_bboxpick run --profile full --bbox-mode "${BBOX_MODE:-mask}" "${amp_flag[@]}"
