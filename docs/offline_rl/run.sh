#!/usr/bin/env bash
# Offline RL against imitation (issue 15, paper sections 6.2-6.3): advantage-weighted fine-tuning (AWR) and
# PA-RL relabelling of the shipped checkpoint with the paper's critic (IQL on the policy's rollouts, failures
# kept), each against a plain behaviour-cloning fine-tune on the same data and steps (the control: new
# expert demos alone may move the table). Choice on validation seeds 5000-5029, then test seeds 10000-10029.
# Run from the repository root; STEP=<name> runs one step (data, critic, finetune, relabel, val, test).
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id
DATA=outputs/cf_data/rl
IQL=outputs/cf_iql/checkpoints/last/pretrained_model
OUT=outputs/offline_rl
STEP=${STEP:-all}
want() { [[ $STEP == all || $STEP == "$1" ]]; }

# 1. The critic's data and critic: exactly docs/counterfactual/run.sh step 2 (expert demos on training seeds
#    2000-2029 of three settings, 6 rollouts per setting on seeds 3000-3005, merged; IQL on the frozen encoder).
if want data; then
    bboxpick-collect --repo_id=local/cf_expert --root=outputs/cf_data/expert --settings=$SETTINGS --episodes=30 \
        --seed_start=2000 --workers=2
    bboxpick-rollouts --policy_path=$CKPT --repo_id=local/cf_rl --root=$DATA --settings=$SETTINGS \
        --episodes=6 --seed_start=3000 --workers=2 --merge_with=outputs/cf_data/expert \
        --stats_png=docs/counterfactual/iql_dataset_stats.png
fi
if want critic; then
    bboxpick-train-critic --dataset.repo_id=local/cf_rl --dataset.root=$DATA --policy_path=$CKPT \
        --output_dir=outputs/cf_iql --overwrite=true
fi

# 2. Fine-tunes from the shipped checkpoint on that dataset: 600 steps of batch 32 (19,200 samples, ~1 epoch),
#    AdamW 1e-4 with 50 warm-up steps, EMA, float32 (so the suite samples as the IL rows did).
source docs/finetune.sh
finetune() { finetune_from $CKPT local/cf_rl $DATA $OUT "$@"; }  # name, extra lerobot-train arguments...
if want finetune; then
    mkdir -p $OUT
    finetune bc_ft
    finetune awr_t01 --policy.awr_critic_path=$IQL --policy.awr_temperature=0.1 --policy.anchor_policy_path=$CKPT
    finetune awr_t003 --policy.awr_critic_path=$IQL --policy.awr_temperature=0.03 --policy.anchor_policy_path=$CKPT
fi
if want relabel; then
    bboxpick-parl-relabel --repo_id=local/cf_rl --root=$DATA --policy_path=$CKPT --critic_path=$IQL \
        --num_inference_steps=4 --out=$OUT/parl_round1.safetensors
    finetune parl --policy.parl_cache_path=$OUT/parl_round1.safetensors --policy.anchor_policy_path=$CKPT
fi

# 3. Validation suites beside docs/counterfactual/val_cf/il (same seeds, settings and 4 DDIM steps).
VAL="--settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2"
if want val; then
    for name in ${VAL_POLICIES:-bc_ft awr_t01 awr_t003 parl}; do
        bboxpick-suite --policies=$name=$OUT/$name/checkpoints/last/pretrained_model $VAL \
            --out_dir=outputs/val_offline_rl/$name
        mkdir -p docs/offline_rl/val/$name
        cp outputs/val_offline_rl/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/offline_rl/val/$name/
    done
fi

# 4. Test seeds, all six settings, beside docs/counterfactual/test_cf/il and il_other3 (the IL rows).
TEST="--settings=grid_id,grid_ood,pile_id,random_id,identical_2,identical_4 --episodes=30 --seed_start=10000 \
    --videos=0 --num_inference_steps=4 --workers=2"
if want test; then
    for name in ${TEST_POLICIES:-bc_ft awr_t01 parl}; do
        bboxpick-suite --policies=$name=$OUT/$name/checkpoints/last/pretrained_model $TEST \
            --out_dir=outputs/test_offline_rl/$name
        mkdir -p docs/offline_rl/test/$name
        cp outputs/test_offline_rl/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/offline_rl/test/$name/
    done
fi

# 5. One table: Pick (Wrong) per setting on test seeds, IL beside each method, and the paired count over the
#    same scenes (scenes the method picks and IL does not / IL picks and the method does not), pooled sign test.
if want test || [[ $STEP == table ]]; then
    IL=docs/counterfactual/test_cf/il,docs/counterfactual/test_cf/il_other3
    bboxpick-compare --runs="IL=$IL;BC-FT=docs/offline_rl/test/bc_ft;AWR (T = 0.1)=docs/offline_rl/test/awr_t01;\
PA-RL=docs/offline_rl/test/parl" --out=docs/offline_rl/test_table.md
fi
