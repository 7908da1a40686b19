#!/usr/bin/env bash
# Issue 16's policy improvement with measured advantages: the counterfactual branch data's successes, each
# weighted by its Monte-Carlo advantage G - V (V: the mean return of the IL policy's own draws at the branch
# point), against the honest baseline (the same successes added to the imitation data, plain BC) and IL.
# Choice on validation seeds 5000-5029, then test seeds 10000-10029. Run from the repository root;
# STEP=<name> runs one step (data, merge, finetune, val, test, table).
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id
CF=outputs/cf_main
TRAIN=outputs/branch_awr/train
OUT=outputs/branch_awr
STEP=${STEP:-all}
want() { [[ $STEP == all || $STEP == "$1" ]]; }

# 1. Branch data: docs/counterfactual/run.sh step 1 (training seeds 1000-1007 of the three settings; 96
#    points, 13 candidates each), recording every picking branch as an episode (--success_demos=true), and
#    the 30 expert demos of docs/offline_rl/run.sh (training seeds 2000+).
if want data; then
    bboxpick-counterfactual --policy_path=$CKPT --settings=$SETTINGS --episodes=8 --seed_start=1000 --samples=3 \
        --out_dir=$CF --workers=2 --success_demos=true
    [[ -f outputs/cf_data/expert/meta/info.json ]] || bboxpick-collect --repo_id=local/cf_expert \
        --root=outputs/cf_data/expert --settings=$SETTINGS --episodes=30 --seed_start=2000 --workers=2
fi

# 2. One training dataset, with LeRobot's own merge: the expert demos first, the picking branches last (the
#    layout bboxpick-branch-advantages checks), then each episode's measured advantage.
if want merge; then
    rm -rf $TRAIN
    lerobot-edit-dataset --new_repo_id=local/branch_awr --new_root=$TRAIN --operation.type=merge \
        --operation.repo_ids="['local/cf_expert', 'local/counterfactual_successes']" \
        --operation.roots="['outputs/cf_data/expert', '$CF/success_demos']" > $OUT.merge.log 2>&1
    bboxpick-branch-advantages --data_dir=$CF --dataset_root=$TRAIN --out=$OUT/advantages.json
    mkdir -p docs/branch_awr && cp $OUT/advantages.json docs/branch_awr/advantages.json
    cp $CF/summary.md docs/branch_awr/branch_summary.md
fi

# 3. Fine-tunes from the shipped checkpoint, docs/offline_rl's settings: 600 steps of batch 32, AdamW 1e-4
#    with 50 warm-up steps, EMA, float32.
source docs/finetune.sh
finetune() { finetune_from $CKPT local/branch_awr $TRAIN $OUT "$@"; }  # name, extra lerobot-train arguments...
if want finetune; then
    mkdir -p $OUT
    AWR_T01=(--policy.awr_advantages_path=$OUT/advantages.json --policy.awr_temperature=0.1
        --policy.anchor_policy_path=$CKPT)
    for name in ${FINETUNES:-succ_bc awr_t01}; do
        case $name in
            succ_bc) finetune succ_bc ;;  # the honest baseline: demos + successes, plain BC
            awr_t01) finetune awr_t01 "${AWR_T01[@]}" ;;
            # a second training seed of the chosen method (lerobot-train's default is 1000)
            awr_t01_s1) finetune awr_t01_s1 "${AWR_T01[@]}" --seed=1 ;;
            succ_bc_s1) finetune succ_bc_s1 --seed=1 ;;
            awr_t003) finetune awr_t003 --policy.awr_advantages_path=$OUT/advantages.json \
                --policy.awr_temperature=0.03 --policy.anchor_policy_path=$CKPT ;;
        esac
    done
fi

# 4-5. Suites: each fine-tune's, beside the IL rows of docs/counterfactual (same seeds, settings and 4 DDIM
#    steps); the table compares them with bboxpick-compare.
suites() {  # split (val|test), IL runs, policies, bboxpick-suite arguments...
    local split=$1 il=$2 policies=$3; shift 3
    local runs="IL=$il"
    for name in $policies; do
        if want "$split"; then
            bboxpick-suite --policies=$name=$OUT/$name/checkpoints/last/pretrained_model "$@" \
                --out_dir=outputs/${split}_branch_awr/$name
            mkdir -p docs/branch_awr/$split/$name
            cp outputs/${split}_branch_awr/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} \
                docs/branch_awr/$split/$name/
        fi
        runs="$runs;$name=docs/branch_awr/$split/$name"
    done
    if want "$split" || [[ $STEP == table ]]; then
        bboxpick-compare --runs="$runs" --out=docs/branch_awr/${split}_table.md
    fi
}
# Validation seeds 5000-5029, the three settings of the branch data.
suites val docs/counterfactual/val_cf/il "${VAL_POLICIES:-succ_bc awr_t01}" --settings=$SETTINGS \
    --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2
# Test seeds 10000-10029, all six settings.
suites test docs/counterfactual/test_cf/il,docs/counterfactual/test_cf/il_other3 \
    "${TEST_POLICIES:-succ_bc awr_t01}" --settings=grid_id,grid_ood,pile_id,random_id,identical_2,identical_4 \
    --episodes=30 --seed_start=10000 --videos=0 --num_inference_steps=4 --workers=2
