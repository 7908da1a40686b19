#!/usr/bin/env bash
# Q-guided diffusion (issue 15: paper section 4.2, item 2) with the paper's critic (IQL, run.sh step 2),
# against the imitation policy. Choice on validation seeds 5000-5029 (rule fixed beforehand, as in suites.sh:
# the largest grid_ood + random_id Pick with Wrong not higher than IL), then the chosen one on test seeds
# 10000-10029. The IL rows are suites.sh's tables (same checkpoint, seeds, settings and 4 DDIM steps).
# Scales: the IQL critic's action gradient is 0.0044 per element on average (scaled units; probe on 2
# validation episodes), so scale 2 moves ~0.009 per denoising step and scale 10 mostly hits the bound
# (0.02 = 3 mm of position per step).
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
# The IQL critic of run.sh step 2 (expert demos, the policy's rollouts, bboxpick-train-critic; ~20 min).
IQL=outputs/cf_iql/checkpoints/last/pretrained_model
SETTINGS=random_id,grid_ood,pile_id
VAL="--settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2"
for scale in 2 10; do
    bboxpick-suite --policies=guided_iql_s$scale=$CKPT $VAL --critic_path=$IQL --rerank_samples=1 \
        --guidance_scale=$scale --guidance_max_step=0.02 --out_dir=outputs/val_cf/guided_iql_s$scale
    mkdir -p docs/counterfactual/val_cf/guided_iql_s$scale
    cp outputs/val_cf/guided_iql_s$scale/{table.md,table.csv,episodes.jsonl,outcomes.png} \
        docs/counterfactual/val_cf/guided_iql_s$scale/
done
# Test seeds: the chosen scale (10) on all six settings; IL on the three settings suites.sh did not run.
TEST="--episodes=30 --seed_start=10000 --videos=1 --num_inference_steps=4 --workers=2"
bboxpick-suite --policies=guided_iql_s10=$CKPT --settings=$SETTINGS,grid_id,identical_2,identical_4 $TEST \
    --critic_path=$IQL --rerank_samples=1 --guidance_scale=10 --guidance_max_step=0.02 \
    --out_dir=outputs/test_cf/guided_iql_s10
bboxpick-suite --policies=il=$CKPT --settings=grid_id,identical_2,identical_4 $TEST --out_dir=outputs/test_cf/il_other3
# The paper's reranking with this same (retrained) critic, as the control.
bboxpick-suite --policies=rerank_draws_iql_retrained=$CKPT --settings=$SETTINGS $TEST --videos=0 --critic_path=$IQL \
    --rerank_samples=4 --out_dir=outputs/test_cf/rerank_draws_iql_retrained
for run in test_cf/guided_iql_s10 test_cf/il_other3 test_cf/rerank_draws_iql_retrained; do
    mkdir -p docs/counterfactual/$run
    cp outputs/$run/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/counterfactual/$run/
done
