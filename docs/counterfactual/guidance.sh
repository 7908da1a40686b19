#!/usr/bin/env bash
# Q-guided diffusion (issue 15, section 4.2 item 2) with the Monte-Carlo critic of run.sh step 3, against the
# imitation policy. The branch data and the critic are regenerated first (deterministic: the same 96 points).
# Choice on validation seeds 5000-5029 (rule fixed beforehand, as in suites.sh: the largest grid_ood +
# random_id Pick with Wrong not higher than IL), then the chosen one on test seeds 10000-10029. IL rows: the
# tables of suites.sh (same checkpoint, seeds and 4 DDIM steps).
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id
# run.sh steps 1 and 3 (40 + 5 min here).
bboxpick-counterfactual --policy_path=$CKPT --settings=$SETTINGS --episodes=8 --seed_start=1000 --samples=3 \
    --out_dir=outputs/cf_main --workers=2
bboxpick-train-mc-critic --data_dir=outputs/cf_main --output_dir=outputs/cf_mc --overwrite=true
CRITIC=outputs/cf_mc/checkpoints/last/pretrained_model
VAL="--settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2"
for scale in 1 10; do
    bboxpick-suite --policies=guided_s$scale=$CKPT $VAL --critic_path=$CRITIC --rerank_samples=1 \
        --guidance_scale=$scale --guidance_max_step=0.02 --out_dir=outputs/val_cf/guided_s$scale
done
