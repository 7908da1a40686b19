#!/usr/bin/env bash
# Issue 16's improvement on the paper protocol's IL policy (grid-only demos, docs/results/recipe_seed1): the
# picking branches of simulator branch points, each weighted by its measured advantage G - V (awr_t01),
# against adding the same successes to the imitation data (succ_bc, the honest baseline) and against IL.
# The goal settings are grid_ood and random_id, where this IL policy picks 37% and 53% of test scenes.
# Choice on validation seeds 5000-5029, then test seeds 10000-10029. Every policy runs the checkpoint's
# own 16 DDIM steps, as the IL test rows did. Run from the repository root; STEP=<name> runs one step
# (data, data_own, merge, merge_own, dagger, dagger2, finetune, val, test, table, table_il_more).
set -euo pipefail
source scripts/setup.sh
RUN=outputs/recipe_seed1/full  # STEP=recipe_seed1 of docs/results/run.sh
CKPT=$RUN/train/checkpoints/last/pretrained_model
CF=outputs/cf_recipe
TRAIN=outputs/branch_recipe/train
OUT=outputs/branch_recipe
DOCS=docs/branch_recipe
IL_MORE=$OUT/il_more/checkpoints/last/pretrained_model  # the train-longer control, base of the last section
STEP=${STEP:-all}
want() { [[ $STEP == all || $STEP == "$1" ]]; }

# 1. Branch data: training seeds 1000-1007 of the two goal settings, chunk boundaries 0, 2, 4, 6, 13
#    candidates per point (the policy's chunk, 3 more draws, ±3 cm x/y/z, ±20° yaw, the expert's chunk),
#    every picking branch recorded as an episode.
if want data; then
    bboxpick-counterfactual --policy_path=$CKPT --settings=grid_ood,random_id --episodes=8 --seed_start=1000 \
        --samples=3 --num_inference_steps=16 --out_dir=$CF --workers=2 --success_demos=true
fi

# 2. The training set: the IL policy's own 200 grid demos first, the picking branches last (the layout
#    bboxpick-branch-advantages checks), merged with LeRobot's own tool; then each episode's advantage.
if want merge; then
    rm -rf $TRAIN && mkdir -p $OUT $DOCS
    lerobot-edit-dataset --new_repo_id=local/branch_recipe --new_root=$TRAIN --operation.type=merge \
        --operation.repo_ids="['local/lego_pick_full', 'local/counterfactual_successes']" \
        --operation.roots="['$RUN/data', '$CF/success_demos']" > $OUT.merge.log 2>&1
    bboxpick-branch-advantages --data_dir=$CF --dataset_root=$TRAIN --out=$OUT/advantages.json
    cp $OUT/advantages.json $DOCS/advantages.json
    cp $CF/summary.md $DOCS/branch_summary.md
fi

# 2a. The same branch data from il_more's own rollouts (the last section's first untried item): its branches,
#     merged after the IL demos, are what il_more does and what then picks, not what the weaker IL did.
CF_OWN=outputs/cf_il_more
TRAIN_OWN=$OUT/train_own
if want data_own; then
    bboxpick-counterfactual --policy_path=$IL_MORE --settings=grid_ood,random_id --episodes=8 --seed_start=1000 \
        --samples=3 --num_inference_steps=16 --out_dir=$CF_OWN --workers=2 --success_demos=true
    cp $CF_OWN/summary.md $DOCS/branch_summary_il_more.md
fi
if want merge_own; then
    rm -rf $TRAIN_OWN
    lerobot-edit-dataset --new_repo_id=local/branch_recipe_own --new_root=$TRAIN_OWN --operation.type=merge \
        --operation.repo_ids="['local/lego_pick_full', 'local/counterfactual_successes']" \
        --operation.roots="['$RUN/data', '$CF_OWN/success_demos']" > $OUT.merge_own.log 2>&1
fi

# 2b. Recovery labels where the branches have none: the IL policy drives on training seeds 4000+ of the goal
#     settings, the scripted expert takes over in place where docs/dagger's intervention rule sees the pick
#     going wrong (off the grasp when low, closing high, 8 s without a pick), and 20 corrections per setting
#     join the branch training set (succ_dagger) or the IL demos alone (dagger_only, the control).
if want dagger; then
    [[ -d $OUT/dagger_corr ]] || bboxpick-dagger --policy_path=$CKPT --repo_id=local/dagger_corr \
        --root=$OUT/dagger_corr --settings=grid_ood,random_id --episodes=20 --seed_start=4000 \
        --num_inference_steps=16 --workers=2 --correction=in_place
    for pair in "succ_dagger:$TRAIN:local/branch_recipe" "dagger_only:$RUN/data:local/lego_pick_full"; do
        IFS=: read -r name base base_id <<< "$pair"
        [[ -d $OUT/${name}_data ]] || lerobot-edit-dataset --new_repo_id=local/${name}_data \
            --new_root=$OUT/${name}_data --operation.type=merge \
            --operation.repo_ids="['$base_id', 'local/dagger_corr']" \
            --operation.roots="['$base', '$OUT/dagger_corr']" > $OUT/${name}.merge.log 2>&1
    done
fi

# 2c. DAgger's second round (aggregation): the chosen succ_dagger policy drives on training seeds 4100+ of the
#     goal settings, the expert corrects in place by the same rule, 40 corrections per setting join
#     succ_dagger's training set (succ_dagger2), and the fine-tune starts from the IL checkpoint as before.
if want dagger2; then
    [[ -d $OUT/dagger_corr2 ]] || bboxpick-dagger --policy_path=$OUT/succ_dagger/checkpoints/last/pretrained_model \
        --repo_id=local/dagger_corr2 --root=$OUT/dagger_corr2 --settings=grid_ood,random_id --episodes=40 \
        --seed_start=4100 --num_inference_steps=16 --workers=2 --correction=in_place
    [[ -d $OUT/succ_dagger2_data ]] || lerobot-edit-dataset --new_repo_id=local/succ_dagger2_data \
        --new_root=$OUT/succ_dagger2_data --operation.type=merge \
        --operation.repo_ids="['local/succ_dagger_data', 'local/dagger_corr2']" \
        --operation.roots="['$OUT/succ_dagger_data', '$OUT/dagger_corr2']" > $OUT/succ_dagger2.merge.log 2>&1
fi

# 3. Fine-tunes from the IL checkpoint with docs/branch_awr's settings: 600 steps of batch 32, AdamW 1e-4
#    with 50 warm-up steps, EMA, float32.
source docs/finetune.sh
finetune() { finetune_from $CKPT local/branch_recipe $TRAIN $OUT "$@"; }  # name, extra lerobot-train arguments...
if want finetune; then
    for name in ${FINETUNES:-succ_bc awr_t01}; do
        case $name in
            succ_bc) finetune succ_bc ;;
            awr_t01) finetune awr_t01 --policy.awr_advantages_path=$OUT/advantages.json \
                --policy.awr_temperature=0.1 --policy.anchor_policy_path=$CKPT ;;
            succ_bc_s1) finetune succ_bc_s1 --seed=1 ;;  # the chosen method's second training seed
            succ_dagger | dagger_only | succ_dagger2) finetune_from $CKPT local/${name}_data $OUT/${name}_data $OUT $name ;;
            succ_dagger_s1) finetune_from $CKPT local/succ_dagger_data $OUT/succ_dagger_data $OUT $name --seed=1 ;;
            succ_dagger_s2) finetune_from $CKPT local/succ_dagger_data $OUT/succ_dagger_data $OUT $name --seed=2 ;;
            # The control: the same 600 steps on the IL policy's own demos only (what training longer gives).
            il_more) finetune_from $CKPT local/lego_pick_full $RUN/data $OUT $name ;;
            # With il_more as the base: the branch successes (il_more_bc) against 600 more steps on the IL
            # demos alone (il_more2), so the method is credited only with what the data adds.
            il_more_bc) finetune_from $IL_MORE local/branch_recipe $TRAIN $OUT $name ;;
            il_more2) finetune_from $IL_MORE local/lego_pick_full $RUN/data $OUT $name ;;
            # From il_more, the IL demos + the picking branches of il_more's own rollouts (step 2a).
            il_more_own) finetune_from $IL_MORE local/branch_recipe_own $TRAIN_OWN $OUT $name ;;
        esac
    done
fi

# 4-5. Suites with the oracle box; bboxpick-compare pairs each policy's scenes with IL's.
suite() {  # split, name, checkpoint, bboxpick-suite arguments...
    local split=$1 name=$2 ckpt=$3; shift 3
    bboxpick-suite --policies=$name=$ckpt --episodes=30 --videos=0 --workers=2 "$@" \
        --out_dir=outputs/${split}_branch_recipe/$name
    mkdir -p $DOCS/$split/$name
    cp outputs/${split}_branch_recipe/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} $DOCS/$split/$name/
}
VAL=(--settings=grid_ood,random_id --seed_start=5000)
if want val; then
    [[ -f $DOCS/val/IL/episodes.jsonl ]] || suite val IL $CKPT "${VAL[@]}"
    for name in ${VAL_POLICIES:-succ_bc awr_t01}; do
        suite val $name $OUT/$name/checkpoints/last/pretrained_model "${VAL[@]}"
    done
fi
if want val || want table; then
    runs="IL=$DOCS/val/IL"
    for name in $(ls $DOCS/val | grep -v '^IL$'); do runs="$runs;$name=$DOCS/val/$name"; done
    bboxpick-compare --runs="$runs" --out=$DOCS/val_table.md
fi
# Test seeds 10000-10029, all six settings; IL's rows are docs/results/recipe_seed1's (the same checkpoint,
# seeds, settings and steps).
if want test; then
    for name in ${TEST_POLICIES:-succ_bc awr_t01}; do
        [[ -f $DOCS/test/$name/episodes.jsonl ]] ||
            suite test $name $OUT/$name/checkpoints/last/pretrained_model --seed_start=10000 \
                ${TEST_SETTINGS:+--settings=$TEST_SETTINGS}  # default: all six settings
    done
fi
# IL's own spread on the test seeds: the same checkpoint with only its noise redrawn (seed + 100000).
if want test_il_resampled; then
    [[ -f $DOCS/test/IL_resampled/episodes.jsonl ]] ||
        suite test IL_resampled $CKPT --seed_start=10000 --policy_seed_offset=100000
fi
if want test || want table; then
    runs="IL=docs/results/recipe_seed1@bbox_diffusion"
    for name in $(ls $DOCS/test); do runs="$runs;$name=$DOCS/test/$name"; done
    bboxpick-compare --runs="$runs" --out=$DOCS/test_table.md
fi
# The last section's tables, paired against il_more (the base) instead of IL.
if want table_il_more; then
    for split in val test; do
        runs="il_more=$DOCS/$split/il_more"
        for name in il_more2 il_more_bc il_more_own; do
            [[ -d $DOCS/$split/$name ]] && runs="$runs;$name=$DOCS/$split/$name"
        done
        bboxpick-compare --runs="$runs" --out=$DOCS/${split}_table_il_more.md
    done
fi
