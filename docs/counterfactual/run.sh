#!/usr/bin/env bash
# The counterfactual study (issue 16), in the order it was run: branch data from the shipped checkpoint, an
# IQL critic trained the paper's way on the same policy's rollouts, a Monte-Carlo critic whose report
# evaluates both on the same held-out branch points, Q-reranking suites (suites.sh), then more branch data
# and a second MC critic. Run from the repository root; times are this 2-core machine's.
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id

# 1. Counterfactual branch points: training seeds 1000-1007 of the three settings, 13 candidates at 4 points
#    per episode, each followed to its outcome (96 points, 1,248 branches, 40 min).
bboxpick-counterfactual --policy_path=$CKPT --settings=$SETTINGS --episodes=8 --seed_start=1000 --samples=3 \
    --out_dir=outputs/cf_main --workers=2

# 2. The paper's way, for comparison: the same policy's rollouts (failures kept) merged with expert demos,
#    and an IQL critic on the same frozen encoder (~8 min).
bboxpick-collect --repo_id=local/cf_expert --root=outputs/cf_data/expert --settings=$SETTINGS --episodes=30 \
    --seed_start=2000 --workers=2
bboxpick-rollouts --policy_path=$CKPT --repo_id=local/cf_rl --root=outputs/cf_data/rl --settings=$SETTINGS \
    --episodes=6 --seed_start=3000 --workers=2 --merge_with=outputs/cf_data/expert \
    --stats_png=docs/counterfactual/iql_dataset_stats.png
bboxpick-train-critic --dataset.repo_id=local/cf_rl --dataset.root=outputs/cf_data/rl --policy_path=$CKPT \
    --output_dir=outputs/cf_iql --overwrite=true
IQL=outputs/cf_iql/checkpoints/last/pretrained_model

# 3. The Monte-Carlo critic on the 96 points (the one suites.sh reranks with), both critics in its report.
bboxpick-train-mc-critic --data_dir=outputs/cf_main --output_dir=outputs/cf_mc --overwrite=true \
    --compare_critic_path=$IQL
mkdir -p docs/counterfactual/critics
cp outputs/cf_mc/mc_report.md docs/counterfactual/critics/mc_report_96points_vs_iql.md
cp outputs/cf_mc/mc_report.json docs/counterfactual/critics/mc_report_96points_vs_iql.json

# 4. Q-reranking suites: validation choice, then test seeds.
bash docs/counterfactual/suites.sh

# 5. More branch points where there is room (random_id, pile_id: seeds 1008-1013, into the same folder: it
#    resumes; 144 points in all, 20 more minutes), a second MC critic and its validation suite.
bboxpick-counterfactual --policy_path=$CKPT --settings=random_id,pile_id --episodes=14 --seed_start=1000 \
    --samples=3 --out_dir=outputs/cf_main --workers=2
cp outputs/cf_main/summary.md docs/counterfactual/branch_summary.md
bboxpick-train-mc-critic --data_dir=outputs/cf_main --output_dir=outputs/cf_mc2 --overwrite=true \
    --compare_critic_path=$IQL
cp outputs/cf_mc2/mc_report.md docs/counterfactual/critics/mc_report_144points_vs_iql.md
cp outputs/cf_mc2/mc_report.json docs/counterfactual/critics/mc_report_144points_vs_iql.json
bboxpick-suite --policies=rerank_draws_mc2=$CKPT --settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 \
    --num_inference_steps=4 --workers=2 --critic_path=outputs/cf_mc2/checkpoints/last/pretrained_model \
    --rerank_samples=4 --out_dir=outputs/val_cf/rerank_draws_mc2
mkdir -p docs/counterfactual/val_cf/rerank_draws_mc2
cp outputs/val_cf/rerank_draws_mc2/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/counterfactual/val_cf/rerank_draws_mc2/

# 6. The paper's Q-reranking with the paper's critic (IQL), for comparison: validation, then test seeds.
for split in "val_cf 5000" "test_cf 10000"; do
    set -- $split
    bboxpick-suite --policies=rerank_draws_iql=$CKPT --settings=$SETTINGS --episodes=30 --seed_start=$2 --videos=0 \
        --num_inference_steps=4 --workers=2 --critic_path=$IQL --rerank_samples=4 --out_dir=outputs/$1/rerank_draws_iql
    mkdir -p docs/counterfactual/$1/rerank_draws_iql
    cp outputs/$1/rerank_draws_iql/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/counterfactual/$1/rerank_draws_iql/
done
