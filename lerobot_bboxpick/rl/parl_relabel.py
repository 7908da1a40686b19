"""``bboxpick-parl-relabel``: PA-RL's relabelling pass over a LeRobotDataset (``rl.pa_rl``).

    bboxpick-parl-relabel --repo_id=local/rl --root=outputs/datasets/rl --policy_path=<checkpoint> \
        --critic_path=outputs/critic/checkpoints/last/pretrained_model --out=outputs/parl/round1.safetensors
    lerobot-train --policy.path=<checkpoint> --policy.parl_cache_path=outputs/parl/round1.safetensors \
        --policy.anchor_policy_path=<checkpoint> --dataset.repo_id=local/rl --dataset.root=<root> ...

Every ``frame_stride``-th frame gets ``samples`` draws of the policy, the dataset's chunk, the critic's
global rerank and local ascent (``ChunkOptimiser``); the cache (``out``) holds the chosen chunks with their
validity, and ``out`` with a ``.json`` suffix the paper's diagnostics. Relabel again with the fine-tuned
checkpoint for the next round (the paper relabels periodically).
"""

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import draccus
import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_bboxpick.rl.critic_dataset import iter_episode_images, load_frame_table, obs_batch
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel, load_policy
from lerobot_bboxpick.rl.pa_rl import ChunkOptimiser, RelabelCache, Relabelled, diagnostics
from lerobot_bboxpick.rl.rerank import sample_chunks

log = logging.getLogger(__name__)


@dataclass
class ParlRelabelConfig:
    """Options of ``bboxpick-parl-relabel``."""

    repo_id: str = "local/rl"
    root: Path | None = None  # local dataset folder (None: LeRobot's cache for repo_id)
    policy_path: Path | None = None  # the bbox_diffusion checkpoint that proposes chunks
    critic_path: Path | None = None  # an IQL / Monte-Carlo critic checkpoint of that policy's encoder
    out: Path = Path("outputs/parl/relabels.safetensors")
    frame_stride: int = 4  # relabel every this-many-th frame; the others keep the dataset's chunk
    samples: int = 4  # policy draws per frame (the dataset's chunk is always a candidate too)
    num_inference_steps: int | None = None  # denoising steps per draw (None: the checkpoint's)
    top_k: int = 2
    ascent_steps: int = 10
    step_size: float = 1e-3
    max_offset: float = 0.03
    batch_size: int = 16  # frames per forward pass
    seed: int = 0
    progress: bool = True

    def __post_init__(self) -> None:
        for name in ("policy_path", "critic_path"):
            if getattr(self, name) is None:
                raise ValueError(f"{name} is required (a checkpoint folder)")
        for name in ("frame_stride", "samples", "batch_size", "num_inference_steps"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 1")
        self.out = Path(self.out)


def chunk_rows(rows: np.ndarray, end: int, horizon: int) -> np.ndarray:
    """``(N, horizon)`` rows of each frame's action chunk, the episode's last row repeated past ``end``
    (LeRobotDataset's padding: the chunk holds the final action)."""
    return np.minimum(rows[:, None] + np.arange(horizon)[None, :], end - 1)


def relabel_dataset(cfg: ParlRelabelConfig) -> dict:
    """Relabel the dataset, save the cache and its diagnostics; returns the diagnostics."""
    dataset = LeRobotDataset(cfg.repo_id, root=cfg.root)
    table = load_frame_table(dataset)
    frame_index = dataset.hf_dataset.select_columns(["index"]).with_format("numpy")[:]["index"].reshape(-1)
    # Propose what the evaluated policy would (the suite samples with --num_inference_steps too).
    policy = load_policy(cfg.policy_path, cfg.num_inference_steps).eval()
    critic = IqlCriticModel.from_pretrained(cfg.critic_path)
    pc, cc = policy.config, critic.encoder.config
    if (pc.horizon, pc.n_obs_steps) != (cc.horizon, cc.n_obs_steps):
        raise ValueError(
            f"critic_path's encoder has horizon/n_obs_steps {(cc.horizon, cc.n_obs_steps)}, "
            f"policy_path's {(pc.horizon, pc.n_obs_steps)}"
        )
    optimiser = ChunkOptimiser(critic, cfg.top_k, cfg.ascent_steps, cfg.step_size, cfg.max_offset)
    generator = torch.Generator().manual_seed(cfg.seed)
    parts: list[Relabelled] = []
    rows_done: list[np.ndarray] = []
    for a, images in iter_episode_images(dataset, table, cfg.progress):
        end = a + len(images)
        rows = np.arange(a, end, cfg.frame_stride)
        for i in range(0, len(rows), cfg.batch_size):
            batch_rows = rows[i : i + cfg.batch_size]
            obs = obs_batch(
                batch_rows,
                table,
                lambda w, a=a, images=images: images[torch.from_numpy(w - a)],
                pc.n_obs_steps,
            )
            dataset_chunks = torch.from_numpy(table.action[chunk_rows(batch_rows, end, pc.horizon)]).float()
            proposals = sample_chunks(policy, obs, cfg.samples, generator)
            parts.append(optimiser.relabel(obs, proposals, dataset_chunks))
            rows_done.append(batch_rows)
    rows_all = np.concatenate(rows_done)
    cache = RelabelCache(
        torch.from_numpy(frame_index[rows_all]),
        torch.cat([p.actions for p in parts]),
        torch.cat([p.valid for p in parts]),
    )
    cache.save(cfg.out)
    report = {**diagnostics(parts), "config": {k: str(v) for k, v in asdict(cfg).items()}}
    cfg.out.with_suffix(".json").write_text(json.dumps(report, indent=1))
    return report


@draccus.wrap()
def main(cfg: ParlRelabelConfig) -> None:
    """Entry point of ``bboxpick-parl-relabel``."""
    logging.basicConfig(level=logging.INFO)
    report = relabel_dataset(cfg)
    print(json.dumps({k: v for k, v in report.items() if k != "config"}, indent=1))


if __name__ == "__main__":
    main()
