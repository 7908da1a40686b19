#!/usr/bin/env bash
# Q-reranking with the Monte-Carlo critic against the imitation policy (issue 16); step 4 of docs/counterfactual/run.sh.
# Choice on validation seeds 5000-5029 (rule: the largest grid_ood + random_id Pick with Wrong not higher
# than IL), then the chosen one and IL on test seeds 10000-10029. ~4 min per row of 90 episodes here.
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
CRITIC=outputs/cf_mc/checkpoints/last/pretrained_model  # MC critic on the first 96 branch points (run.sh, step 3)
SETTINGS=random_id,grid_ood,pile_id
VAL="--settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2"
bboxpick-suite --policies=il=$CKPT $VAL --out_dir=outputs/val_cf/il
bboxpick-suite --policies=rerank_draws=$CKPT $VAL --critic_path=$CRITIC --rerank_samples=4 --out_dir=outputs/val_cf/rerank_draws
bboxpick-suite --policies=rerank_draws8=$CKPT $VAL --critic_path=$CRITIC --rerank_samples=8 --out_dir=outputs/val_cf/rerank_draws8
bboxpick-suite --policies=rerank_yaw=$CKPT $VAL --critic_path=$CRITIC --rerank_samples=4 \
    --rerank_perturbations=yaw:0.35 --out_dir=outputs/val_cf/rerank_yaw
bboxpick-suite --policies=rerank_residuals=$CKPT --settings=$SETTINGS --episodes=10 --seed_start=5000 --videos=0 \
    --num_inference_steps=4 --workers=2 --critic_path=$CRITIC --rerank_samples=2 \
    --rerank_perturbations=x:0.03,y:0.03,z:0.03,yaw:0.35 --out_dir=outputs/val_cf/rerank_residuals
# Test seeds: IL and the validation's choice (4 draws, no residuals).
TEST="--settings=$SETTINGS --episodes=30 --seed_start=10000 --videos=1 --num_inference_steps=4 --workers=2"
bboxpick-suite --policies=il=$CKPT $TEST --out_dir=outputs/test_cf/il
bboxpick-suite --policies=rerank_draws=$CKPT $TEST --critic_path=$CRITIC --rerank_samples=4 \
    --out_dir=outputs/test_cf/rerank_draws
# The artefacts kept in docs/ (tables, episodes, charts; not the videos and thumbnails).
for run in val_cf/il val_cf/rerank_draws val_cf/rerank_draws8 val_cf/rerank_yaw val_cf/rerank_residuals \
    test_cf/il test_cf/rerank_draws; do
    mkdir -p docs/counterfactual/$run
    cp outputs/$run/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/counterfactual/$run/
done
