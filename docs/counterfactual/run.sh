#!/usr/bin/env bash
# The counterfactual study (issue 16): branch data from the shipped checkpoint, a Monte-Carlo critic beside
# an IQL critic trained the paper's way on the same policy's rollouts, and Q-reranking in the suite.
# Run from the repository root after `bash scripts/setup.sh`. Times are this 2-core machine's.
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id

# 1. Counterfactual branch points (training seeds 1000-1007 per setting; 13 candidates at 4 points per
#    episode, each followed to its outcome; ~5 min per episode per worker).
bboxpick-counterfactual --policy_path=$CKPT --settings=$SETTINGS --episodes=8 --seed_start=1000 --samples=3 \
    --out_dir=outputs/cf_main --workers=2

# 2. The paper's way, for comparison: the same policy's rollouts (failures kept) merged with expert demos,
#    and an IQL critic on the same frozen encoder.
bboxpick-collect --repo_id=local/cf_expert --root=outputs/cf_data/expert --settings=$SETTINGS --episodes=30 \
    --seed_start=2000 --workers=2
bboxpick-rollouts --policy_path=$CKPT --repo_id=local/cf_rl --root=outputs/cf_data/rl --settings=$SETTINGS \
    --episodes=6 --seed_start=3000 --workers=2 --merge_with=outputs/cf_data/expert \
    --stats_png=docs/counterfactual/iql_dataset_stats.png
bboxpick-train-critic --dataset.repo_id=local/cf_rl --dataset.root=outputs/cf_data/rl --policy_path=$CKPT \
    --output_dir=outputs/cf_iql --overwrite=true

# 3. The Monte-Carlo critic; its report evaluates both critics on the same held-out branch points.
bboxpick-train-mc-critic --data_dir=outputs/cf_main --output_dir=outputs/cf_mc --overwrite=true \
    --compare_critic_path=outputs/cf_iql/checkpoints/last/pretrained_model
cp outputs/cf_mc/mc_report.md docs/counterfactual/mc_report.md
cp outputs/cf_main/summary.md docs/counterfactual/branch_summary.md
