#!/usr/bin/env bash
# Advantage-weighted fine-tuning (issue 15, paper section 6.2) of the shipped checkpoint, on validation seeds.
# Data and critic: the paper's way, as docs/counterfactual/run.sh step 2 (30 expert demos of the three hard
# settings, training seeds 2000+, merged with 6 closed-loop rollouts per setting of the checkpoint, failures
# kept, seeds 3000+; an IQL critic on the checkpoint's frozen encoder). Fine-tune: lerobot-train from the
# checkpoint, denoising loss weighted by min(exp(A / 0.1), 20) + the unweighted BC term + the paper's anchor
# (0.5) to the checkpoint itself, 600 steps of batch 32. The IL row to compare with is
# docs/counterfactual/val_cf/il (same seeds, settings and 4 DDIM steps).
# Run from the repository root.
set -euo pipefail
source scripts/setup.sh
CKPT=examples/bbox_diffusion_lego_pick
SETTINGS=random_id,grid_ood,pile_id
if [ ! -f outputs/cf_iql/checkpoints/last/pretrained_model/model.safetensors ]; then
    bboxpick-collect --repo_id=local/cf_expert --root=outputs/cf_data/expert --settings=$SETTINGS --episodes=30 \
        --seed_start=2000 --workers=2 --resume=true
    bboxpick-rollouts --policy_path=$CKPT --repo_id=local/cf_rl --root=outputs/cf_data/rl --settings=$SETTINGS \
        --episodes=6 --seed_start=3000 --workers=2 --merge_with=outputs/cf_data/expert
    bboxpick-train-critic --dataset.repo_id=local/cf_rl --dataset.root=outputs/cf_data/rl --policy_path=$CKPT \
        --output_dir=outputs/cf_iql --overwrite=true
fi
IQL=outputs/cf_iql/checkpoints/last/pretrained_model
if [ ! -f outputs/awr/checkpoints/last/pretrained_model/model.safetensors ]; then
    lerobot-train --policy.path=$CKPT --policy.use_amp=false --policy.awr_critic_path=$IQL \
        --policy.awr_temperature=0.1 --policy.awr_max_weight=20 --policy.awr_bc_weight=1.0 \
        --policy.anchor_policy_path=$CKPT --policy.anchor_weight=0.5 --policy.scheduler_warmup_steps=50 \
        --policy.optimizer_lr=1e-4 --dataset.repo_id=local/cf_rl --dataset.root=outputs/cf_data/rl \
        --output_dir=outputs/awr --steps=600 --batch_size=32 --num_workers=1 --save_freq=600 --log_freq=50 \
        --wandb.enable=false
fi
bboxpick-suite --policies=awr_iql=outputs/awr/checkpoints/last/pretrained_model --settings=$SETTINGS \
    --episodes=30 --seed_start=5000 --videos=0 --num_inference_steps=4 --workers=2 --out_dir=outputs/val_cf/awr_iql
mkdir -p docs/critic/val_awr_iql
cp outputs/val_cf/awr_iql/{table.md,table.csv,episodes.jsonl,outcomes.png} docs/critic/val_awr_iql/
