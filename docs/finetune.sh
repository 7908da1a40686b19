# The studies' fine-tune (docs/offline_rl, docs/branch_awr, docs/branch_recipe): 600 steps of batch 32
# (19,200 samples), AdamW 1e-4 with 50 warm-up steps, EMA, float32 (so the suite samples as the IL rows did).
# FINETUNE_STEPS changes the step count. Sourced from the repository root; skips a fine-tune whose last checkpoint exists.
finetune_from() {  # checkpoint, dataset repo_id, dataset root, out dir, name, extra lerobot-train arguments...
    local ckpt=$1 repo_id=$2 root=$3 out=$4 name=$5; shift 5
    [[ -f $out/$name/checkpoints/last/pretrained_model/model.safetensors ]] && return
    rm -rf "$out/$name"
    lerobot-train --policy.path=$ckpt --policy.use_amp=false --policy.use_ema=true --policy.optimizer_lr=1e-4 \
        --policy.scheduler_warmup_steps=50 --dataset.repo_id=$repo_id --dataset.root=$root \
        --output_dir=$out/$name --steps=${FINETUNE_STEPS:-600} --batch_size=32 --num_workers=1 --save_freq=${FINETUNE_STEPS:-600} --log_freq=50 \
        --wandb.enable=false "$@" > "$out/$name.log" 2>&1
}
