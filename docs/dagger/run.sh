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
    [[ -d $OUT/r1 ]] || bboxpick-dagger --policy_path=$CKPT --repo_id=local/r1 --root=$OUT/r1 \
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
fi

# 3. Validation suites beside docs/counterfactual/val_cf/il (same seeds, settings and 4 DDIM steps).
VAL="--settings=$SETTINGS --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2"
if want val; then
    for name in ${VAL_POLICIES:-demos90_ft dagger_r1_ft}; do
        bboxpick-suite --policies=$name=$OUT/$name/checkpoints/last/pretrained_model $VAL --out_dir=$OUT/val/$name
        mkdir -p docs/dagger/val/$name
        cp $OUT/val/$name/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/dagger/val/$name/
    done
fi
