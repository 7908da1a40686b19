"""``bboxpick-train-critic``: train the IQL critic from any LeRobotDataset with outcome labels.

    python -m lerobot_bboxpick.rl.train_critic --policy_path=outputs/train/checkpoints/last/pretrained_model \
        --dataset.repo_id=local/rollouts --dataset.root=outputs/datasets/rollouts --output_dir=outputs/critic

Paper section 5.3: the encoder is the policy's, frozen and warm-started (``--critic.freeze_encoder=false``
trains it at ``lr * encoder_lr_scale``); AdamW 4e-4, weight decay 1e-4, cosine schedule with 150
warm-up steps, 30 epochs; a 10% validation split by episode evaluated every epoch and bucketed
diagnostics (V/Q/A/TD by outcome and phase, ordering checks) every 3 epochs. With a frozen encoder
every frame is encoded once up front, so an epoch costs only the critic's MLPs.

Output, like a LeRobot training run: ``<output_dir>/checkpoints/<step>/pretrained_model/`` (``config.json``,
``model.safetensors``, ``encoder/config.json``, ``train_config.json``, ``diagnostics.json``), a ``last``
link to it, and ``<output_dir>/diagnostics.jsonl`` with one line per evaluation.
"""

import json
import logging
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import draccus
import numpy as np
import torch
from lerobot.common.train_utils import get_step_checkpoint_dir, update_last_checkpoint
from lerobot.utils.constants import PRETRAINED_MODEL_DIR
from torch import Tensor
from tqdm import tqdm

from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.critic_dataset import (
    CriticDataConfig,
    FrameTable,
    Transitions,
    build_transitions,
    compute_embeddings,
    load_all_images,
    load_frame_table,
    obs_batch,
)
from lerobot_bboxpick.rl.diagnostics import evaluate, format_grouped, summarize
from lerobot_bboxpick.rl.iql import iql_step
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel, load_policy

log = logging.getLogger(__name__)
TRAIN_CONFIG_NAME = "train_config.json"
DIAGNOSTICS_NAME = "diagnostics.json"


@dataclass
class TrainCriticConfig:
    """Options of ``bboxpick-train-critic``."""

    dataset: CriticDataConfig = field(default_factory=CriticDataConfig)
    # The bbox_diffusion checkpoint (its pretrained_model folder) whose encoder the critic reuses.
    policy_path: Path | None = None
    critic: IqlCriticConfig = field(default_factory=IqlCriticConfig)
    output_dir: Path = Path("outputs/critic")
    # Refuse to write into an existing output_dir unless this is set (its checkpoints are replaced).
    overwrite: bool = False
    epochs: int = 30
    # If set, train exactly this many steps instead of `epochs` epochs.
    steps: int | None = None
    batch_size: int = 256
    lr: float = 4e-4
    encoder_lr_scale: float = 0.1
    weight_decay: float = 1e-4
    warmup_steps: int = 150
    grad_clip_norm: float = 10.0
    diagnostics_every_epochs: int = 3
    # Frames per forward pass when encoding the dataset.
    embed_batch_size: int = 32
    seed: int = 0
    progress: bool = True

    def __post_init__(self) -> None:
        self.output_dir = Path(self.output_dir)
        self.policy_path = Path(self.policy_path) if self.policy_path is not None else None
        for name in ("epochs", "batch_size", "diagnostics_every_epochs", "embed_batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 1")
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"steps={self.steps} must be >= 1 (or None: train `epochs` epochs)")
        if self.warmup_steps < 0 or self.lr <= 0 or self.encoder_lr_scale < 0 or self.weight_decay < 0:
            raise ValueError("warmup_steps, encoder_lr_scale and weight_decay must be >= 0 and lr > 0")


class StateFeatures:
    """State features of frame rows: a cache for a frozen encoder, the encoder itself otherwise."""

    def __init__(self, model: IqlCriticModel, dataset, table: FrameTable, cfg: TrainCriticConfig) -> None:
        self.model, self.table, self.cfg = model, table, cfg
        self.n_obs = model.encoder.config.n_obs_steps
        self.cache: Tensor | None = None
        self.images: Tensor | None = None
        if model.config.freeze_encoder:
            self.cache = compute_embeddings(
                model.encode, dataset, table, self.n_obs, cfg.embed_batch_size, cfg.progress
            )
        else:
            self.images = load_all_images(dataset, table, cfg.progress)

    def _encode(self, rows: np.ndarray) -> Tensor:
        assert self.images is not None
        images = self.images
        return self.model.encode(
            obs_batch(rows, self.table, lambda w: images[torch.from_numpy(w)].float() / 255, self.n_obs)
        )

    def __call__(self, rows: np.ndarray, grad: bool = False) -> Tensor:
        """Features ``(len(rows), D)``; with ``grad`` (unfrozen encoder) they carry the encoder's graph."""
        if self.cache is not None:
            return self.cache[torch.from_numpy(np.asarray(rows))]
        with torch.set_grad_enabled(grad):
            return self._encode(np.asarray(rows))

    @torch.no_grad()
    def all(self) -> Tensor:
        """Features of every frame (eval mode), for the diagnostics."""
        if self.cache is not None:
            return self.cache
        was_training = self.model.training
        self.model.eval()
        rows = np.arange(self.table.num_frames)
        out = torch.cat(
            [
                self(rows[i : i + self.cfg.embed_batch_size])
                for i in range(0, len(rows), self.cfg.embed_batch_size)
            ]
        )
        self.model.train(was_training)
        return out


def _batch_loss(model: IqlCriticModel, features: StateFeatures, tr: Transitions, idx: np.ndarray, grad: bool):
    s = features(tr.obs_row[idx], grad=grad)
    s_next = features(tr.next_row[idx], grad=False).detach()
    return model.iql_batch(
        s,
        torch.from_numpy(tr.actions[idx]),
        torch.from_numpy(tr.reward[idx]),
        torch.from_numpy(tr.done[idx]),
        torch.from_numpy(tr.discount[idx]),
        s_next,
    )


@torch.no_grad()
def validation_loss(model: IqlCriticModel, features: StateFeatures, tr: Transitions, batch_size: int) -> dict:
    """Mean IQL losses over ``tr`` (no update)."""
    if len(tr) == 0:
        return {}
    sums: dict[str, float] = {}
    for i in range(0, len(tr), batch_size):
        idx = np.arange(i, min(i + batch_size, len(tr)))
        _, m = model.critic.losses(_batch_loss(model, features, tr, idx, grad=False), model.config.expectile)
        for k, v in m.items():
            sums[k] = sums.get(k, 0.0) + v * len(idx)
    return {k: v / len(tr) for k, v in sums.items()}


def diagnose(model: IqlCriticModel, features: StateFeatures, train: Transitions, val: Transitions) -> dict:
    """Test-A summaries (``diagnostics.summarize``) on the training and validation transitions."""
    was_training = model.training
    model.eval()
    emb = features.all()
    out = {
        name: summarize(evaluate(model, emb, tr), tr)
        for name, tr in (("train", train), ("val", val))
        if len(tr)
    }
    model.train(was_training)
    return out


def prepare_output_dir(output_dir: Path, overwrite: bool, stale_files: tuple[str, ...] = ()) -> None:
    """Create ``output_dir``; a non-empty one is refused unless ``overwrite``, and then its checkpoints
    and ``stale_files`` (logs a new run appends to) are removed."""
    if output_dir.exists() and any(output_dir.iterdir()):
        if not overwrite:
            raise FileExistsError(
                f"output_dir={output_dir} is not empty; pass --overwrite=true or another folder"
            )
        shutil.rmtree(output_dir / "checkpoints", ignore_errors=True)
        for name in stale_files:
            (output_dir / name).unlink(missing_ok=True)
    output_dir.mkdir(parents=True, exist_ok=True)


def save_critic_checkpoint(
    model: IqlCriticModel, cfg: object, output_dir: Path, total: int, step: int, extra: dict | None = None
) -> Path:
    """LeRobot's checkpoint layout: ``<output_dir>/checkpoints/<step>/pretrained_model`` with the model,
    ``train_config.json`` (``cfg``) and one JSON file per ``extra`` entry, and the ``last`` link to it;
    returns the ``pretrained_model`` folder."""
    ckpt = get_step_checkpoint_dir(output_dir, total, step)
    pretrained = ckpt / PRETRAINED_MODEL_DIR
    model.save_pretrained(pretrained)
    (pretrained / TRAIN_CONFIG_NAME).write_text(json.dumps(draccus.encode(cfg), indent=4))
    for name, value in (extra or {}).items():
        (pretrained / name).write_text(json.dumps(value, indent=1))
    update_last_checkpoint(ckpt)
    return pretrained


def train_critic(cfg: TrainCriticConfig) -> dict:
    """Train the critic; returns ``{"checkpoint", "steps", "diagnostics", "val_loss", "history"}``."""
    if cfg.policy_path is None:
        raise ValueError(
            "policy_path is required: the bbox_diffusion checkpoint (.../pretrained_model) whose observation "
            "encoder the critic reuses"
        )
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    prepare_output_dir(cfg.output_dir, cfg.overwrite, ("diagnostics.jsonl",))
    with torch.random.fork_rng():  # seeded here without touching the caller's RNG state
        torch.manual_seed(cfg.seed)
        policy = load_policy(cfg.policy_path)
        model = IqlCriticModel.from_policy(cfg.critic, policy)
        pc = policy.config
        del policy
        dataset = LeRobotDataset(cfg.dataset.repo_id, root=cfg.dataset.root)
        table = load_frame_table(dataset)
        stride = cfg.dataset.chunk_stride or pc.n_action_steps
        tr = build_transitions(table, cfg.dataset, pc.horizon, stride, cfg.critic.gamma)
        train, val = tr.subset(~tr.is_val), tr.subset(tr.is_val)
        if len(train) == 0:
            raise ValueError("no training transitions: every episode is in the validation split")
        features = StateFeatures(model, dataset, table, cfg)
        result = _fit(cfg, model, features, train, val)
    return result


def _fit(
    cfg: TrainCriticConfig,
    model: IqlCriticModel,
    features: StateFeatures,
    train: Transitions,
    val: Transitions,
) -> dict:
    from diffusers.optimization import get_cosine_schedule_with_warmup

    steps_per_epoch = math.ceil(len(train) / cfg.batch_size)
    total = cfg.steps if cfg.steps is not None else cfg.epochs * steps_per_epoch
    optimizer = torch.optim.AdamW(
        model.get_optim_params(cfg.lr, cfg.encoder_lr_scale), weight_decay=cfg.weight_decay
    )
    scheduler = get_cosine_schedule_with_warmup(optimizer, min(cfg.warmup_steps, total), total)
    rng = np.random.default_rng(cfg.seed)
    history: list[dict] = []
    diagnostics: dict = {}
    val_metrics: dict = {}
    jsonl = cfg.output_dir / "diagnostics.jsonl"
    model.train()
    bar = tqdm(total=total, desc="critic", unit="step", disable=not cfg.progress)
    step, epoch = 0, 0
    while step < total:
        order = rng.permutation(len(train))
        for i in range(0, len(order), cfg.batch_size):
            if step >= total:
                break
            batch = _batch_loss(model, features, train, order[i : i + cfg.batch_size], grad=True)
            metrics = iql_step(
                model.critic,
                batch,
                optimizer,
                model.config.expectile,
                model.config.polyak,
                cfg.grad_clip_norm,
            )
            scheduler.step()
            step += 1
            bar.update(1)
            bar.set_postfix(v=f"{metrics['v_mean']:.3f}", q_loss=f"{metrics['q_loss']:.4f}", epoch=epoch)
        epoch += 1
        last = step >= total
        model.eval()
        val_metrics = validation_loss(model, features, val, cfg.batch_size)
        record = {"epoch": epoch, "step": step, "train": metrics, "val": val_metrics}
        if epoch % cfg.diagnostics_every_epochs == 0 or last:
            diagnostics = diagnose(model, features, train, val)
            record["diagnostics"] = diagnostics
            for split, summary in diagnostics.items():
                bar.write(
                    f"epoch {epoch} step {step} [{split}] ordering score {summary['ordering_score']} "
                    f"over {len(summary['checks'])} checks\n{format_grouped(summary, 'v')}"
                )
        model.train()
        history.append(record)
        with open(jsonl, "a") as f:
            f.write(json.dumps(record) + "\n")
    bar.close()
    model.eval()
    pretrained = save_critic_checkpoint(
        model, cfg, cfg.output_dir, total, step, {DIAGNOSTICS_NAME: diagnostics}
    )
    return {
        "checkpoint": str(pretrained),
        "steps": step,
        "diagnostics": diagnostics,
        "val_loss": val_metrics,
        "history": history,
    }


@draccus.wrap()
def main(cfg: TrainCriticConfig) -> None:
    """Entry point of ``bboxpick-train-critic``."""
    logging.basicConfig(level=logging.INFO)
    result = train_critic(cfg)
    summary = {split: d["ordering_score"] for split, d in result["diagnostics"].items()}
    print(
        json.dumps(
            {"checkpoint": result["checkpoint"], "steps": result["steps"], "ordering_score": summary},
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
