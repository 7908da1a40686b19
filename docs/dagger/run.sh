#!/usr/bin/env bash
# DAgger rounds in simulation (issue 13): the shipped checkpoint drives, the scripted expert takes over where the
# intervention rule sees the pick going wrong (bboxpick-dagger), and the corrections join the expert demos for a
# fine-tune; against the control of as many new expert demos (plain behaviour cloning). Choice on validation seeds
# 5000-5029, then test seeds 10000-10029. Run from the repository root; STEP=<name> runs one step.
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id
OUT=outputs/dagger
STEP=${STEP:-all}
want() { [[ $STEP == all || $STEP == "$1" ]]; }
mkdir -p $OUT

# 1. Data. The expert demos of docs/offline_rl (training seeds 2000-2029, 10 per setting) are the first 30 of the
#    control's 90 (the same seeds give the same demos). Round 1: rollouts of the shipped checkpoint (4 DDIM steps,
#    as the suite runs it) on training seeds 4000+, 20 corrections per setting, merged after those 30 demos.
if want data; then
    [[ -d $OUT/demos30 ]] || bboxpick-collect --repo_id=local/demos30 --root=$OUT/demos30 \
        --settings=$SETTINGS --episodes=30 --seed_start=2000 --workers=2
    [[ -d $OUT/demos90 ]] || bboxpick-collect --repo_id=local/demos90 --root=$OUT/demos90 \
        --settings=$SETTINGS --episodes=90 --seed_start=2000 --workers=2
    [[ -d $OUT/r1 ]] || bboxpick-dagger --policy_path=$CKPT --repo_id=local/r1 --root=$OUT/r1 --correction=replan \
        --settings=$SETTINGS --episodes=20 --num_inference_steps=4 --workers=2 --merge_with=$OUT/demos30
    # The same round with the expert correcting in place (turn and shift onto the grasp, then descend).
    [[ -d $OUT/r1n ]] || bboxpick-dagger --policy_path=$CKPT --repo_id=local/r1n --root=$OUT/r1n --correction=in_place \
        --settings=$SETTINGS --episodes=20 --num_inference_steps=4 --workers=2 --merge_with=$OUT/demos30
fi

# 2. Fine-tunes from the shipped checkpoint, as docs/offline_rl/run.sh's: 600 steps of batch 32, AdamW 1e-4, 50
#    warm-up steps, EMA, float32.
finetune() {  # name, dataset root, extra lerobot-train arguments...
    local name=$1 root=$2; shift 2
    [[ -f $OUT/$name/checkpoints/last/pretrained_model/model.safetensors ]] && return
    rm -rf "$OUT/$name"
    lerobot-train --policy.path=$CKPT --policy.use_amp=false --policy.use_ema=true --policy.optimizer_lr=1e-4 \
        --policy.scheduler_warmup_steps=50 --dataset.repo_id=local/$(basename "$root") --dataset.root=$root \
        --output_dir=$OUT/$name --steps=600 --batch_size=32 --num_workers=1 --save_freq=600 --log_freq=50 \
        --wandb.enable=false "$@" > "$OUT/$name.log" 2>&1
}
if want finetune; then
    finetune demos90_ft $OUT/demos90
    finetune dagger_r1_ft $OUT/r1
    finetune dagger_r1n_ft $OUT/r1n
fi

# 3. Validation suites beside docs/counterfactual/val_cf/il (same seeds, settings and 4 DDIM steps).
VAL="--settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2"
if want val; then
    for name in ${VAL_POLICIES:-demos90_ft dagger_r1_ft dagger_r1n_ft}; do
        bboxpick-suite --policies=$name=$OUT/$name/checkpoints/last/pretrained_model $VAL --out_dir=$OUT/val/$name
        mkdir -p docs/dagger/val/$name
        cp $OUT/val/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/dagger/val/$name/
    done
fi
if [[ $STEP == val_table ]]; then  # after val and round2
    bboxpick-compare --runs="IL=docs/counterfactual/val_cf/il;BC, 30 + 60 new demos=docs/dagger/val/demos90_ft;\
DAgger r1, replan=docs/dagger/val/dagger_r1_ft;DAgger r1, in place=docs/dagger/val/dagger_r1n_ft;\
DAgger r2, replan=docs/dagger/val/dagger_r2_ft" --out=docs/dagger/val_table.md
fi

# 4. Round 2 (replanning corrections): the round-1 policy drives on the next training seeds (4100+), the corrections join round 1's
#    data (DAgger aggregates), and a fine-tune from the shipped checkpoint on it all, as in step 2.
R1_POLICY=$OUT/dagger_r1_ft/checkpoints/last/pretrained_model
if want round2; then
    [[ -d $OUT/r2 ]] || bboxpick-dagger --policy_path=$R1_POLICY --repo_id=local/r2 --root=$OUT/r2 \
        --settings=$SETTINGS --episodes=20 --seed_start=4100 --num_inference_steps=4 --workers=2 --merge_with=$OUT/r1 \
        --correction=replan
    finetune dagger_r2_ft $OUT/r2
    VAL_POLICIES=dagger_r2_ft STEP=val bash docs/dagger/run.sh
fi

# 5. Test seeds, all six settings, beside docs/counterfactual/test_cf/il and il_other3 (the IL rows), and one
#    table with the paired counts against IL.
TEST="--settings=grid_id,grid_ood,pile_id,random_id,identical_2,identical_4 --episodes=30 --seed_start=10000 \
    --videos=0 --num_inference_steps=4 --workers=2"
if want test; then
    for name in ${TEST_POLICIES:-dagger_r1n_ft}; do  # the validation's choice (the controls: not run on test yet)
        bboxpick-suite --policies=$name=$OUT/$name/checkpoints/last/pretrained_model $TEST --out_dir=$OUT/test/$name
        mkdir -p docs/dagger/test/$name
        cp $OUT/test/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/dagger/test/$name/
    done
fi
if want test || [[ $STEP == table ]]; then
    IL=docs/counterfactual/test_cf/il,docs/counterfactual/test_cf/il_other3
    RUNS="IL=$IL;DAgger r1, in place=docs/dagger/test/dagger_r1n_ft"
    bboxpick-compare --runs="$RUNS" --out=docs/dagger/test_table.md
fi

# 6. How often the rule took over from a policy that would have picked: the shipped checkpoint alone on round
#    1's seeds (the same rollouts up to each takeover: same seeds, same policy noise), joined with round 1's records.
if want rule; then
    [[ -d $OUT/r1_alone ]] || bboxpick-rollouts --policy_path=$CKPT --repo_id=local/r1_alone --root=$OUT/r1_alone \
        --settings=$SETTINGS --episodes=31 --seed_start=4000 --num_inference_steps=4 --workers=2
    python - > docs/dagger/rule_check.md <<'PY'
import json
from collections import Counter
from pathlib import Path

def records(work_dir):
    return {r["seed"]: r for shard in sorted(Path(work_dir).glob("shard_*")) if not shard.name.endswith(".partial")
            for r in json.loads((shard / "seeds.json").read_text())}
dagger, alone = records("outputs/dagger/r1.collect"), records("outputs/dagger/r1_alone.collect")
rows = Counter((d["reason"] or "no takeover", alone[s]["outcome"]) for s, d in dagger.items() if s in alone)
outcomes = ["pick", "wrong", "contact", "empty"]
print("| round 1 (shipped checkpoint, seeds 4000-4092) | " + " | ".join(f"alone: {o}" for o in outcomes) + " |")
print("|---|" + "---|" * len(outcomes))
for reason in ["no takeover", "off_yaw", "off_xy", "closing_high", "patience"]:
    print(f"| {reason} | " + " | ".join(str(rows[reason, o]) for o in outcomes) + " |")
PY
fi
