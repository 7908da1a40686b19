"""PA-RL action relabelling (paper section 6.3; Mark et al., "Policy Agnostic RL", 2024).

For each dataset frame: propose chunks (the policy's draws and the dataset's own chunk), rank them all by
the critic (global step), run a few steps of gradient ascent on Q from the best ``top_k`` (local step,
positions and gripper only, each candidate held within ``max_offset`` of where it started and reverted
when its Q did not improve), and keep the argmax. The result goes into a cache of optimised chunks with
a validity mask (valid: the chosen chunk's Q beats the dataset chunk's), which the policy's training loss
uses in place of the dataset's action where valid (``--policy.parl_cache_path``). Relabelling again with
the fine-tuned policy (``bboxpick-parl-relabel`` between ``lerobot-train`` rounds) is the periodic part.

The diagnostics are the paper's: mean chosen Q, the global Q spread, the revert rate, how often the
dataset's chunk wins, and how far the chosen chunks drift from the dataset's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from lerobot.utils.constants import ACTION
from safetensors.torch import load_file, save_file
from torch import Tensor

from lerobot_bboxpick.geometry import absolute_pose10_torch, relative_pose10_torch
from lerobot_bboxpick.keys import STATE
from lerobot_bboxpick.rl.rerank import rerank_by_q

OPTIMISED_DIMS = [0, 1, 2, 9]  # x, y, z, gripper width: rot6d entries off their manifold are not poses
INDEX = "index"  # LeRobotDataset's global frame index, in every training batch


@dataclass
class Relabelled:
    """Per state: the chosen absolute chunk, whether it beats the dataset's, and the diagnostics' parts."""

    actions: Tensor  # (B, H, 10) absolute
    valid: Tensor  # (B,) bool
    chosen_q: Tensor  # (B,)
    dataset_q: Tensor  # (B,)
    global_spread: Tensor  # (B,) std of Q over the proposals
    dataset_won: Tensor  # (B,) bool: the dataset chunk was the global argmax
    reverted: Tensor  # (B, top_k) bool
    drift: Tensor  # (B, 3) m: the chosen chunk's last position minus the dataset chunk's (world x, y, z)


@dataclass
class ChunkOptimiser:
    """Global Q-rerank of proposals, then bounded local Q-gradient ascent with revert-on-no-improvement."""

    critic: object  # encode(observations), q(features, relative chunk): an IqlCriticModel
    top_k: int = 2
    ascent_steps: int = 10
    step_size: float = 1e-3  # m of position (or width) per unit of dQ/da, per step
    max_offset: float = 0.03  # m: no optimised coordinate moves further than this from its start

    def __post_init__(self) -> None:
        for name in ("top_k", "ascent_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 1")
        for name in ("step_size", "max_offset"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}={getattr(self, name)!r} must be > 0")

    def ascend(self, features: Tensor, start: Tensor, start_q: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Local step from relative chunks ``start`` (M, H, 10) whose Q is ``start_q`` (M,): the optimised
        chunks, their Q, and which were reverted (M,) because their Q did not improve."""
        mask = torch.zeros_like(start)
        mask[..., OPTIMISED_DIMS] = 1.0
        chunk = start.clone()
        with torch.enable_grad():
            for _ in range(self.ascent_steps):
                chunk.requires_grad_(True)
                (grad,) = torch.autograd.grad(self.critic.q(features, chunk).sum(), chunk)
                moved = chunk.detach() + self.step_size * grad * mask
                chunk = start + (moved - start).clamp(-self.max_offset, self.max_offset)
        with torch.no_grad():
            q = self.critic.q(features, chunk)
            reverted = q <= start_q
            chunk = torch.where(reverted[:, None, None], start, chunk)
            q = torch.where(reverted, start_q, q)
        return chunk, q, reverted

    @torch.no_grad()
    def relabel(
        self, observations: dict[str, Tensor], proposals: Tensor, dataset_chunks: Tensor
    ) -> Relabelled:
        """``proposals`` (B, N, H, 10) and ``dataset_chunks`` (B, H, 10), absolute, for ``observations``
        (the policy's input, (B, n_obs, ...))."""
        b, n = proposals.shape[:2]
        current = observations[STATE][:, -1].float()
        candidates = torch.cat([dataset_chunks[:, None], proposals], dim=1).float()  # dataset chunk first
        relative = relative_pose10_torch(candidates, current[:, None])
        features = self.critic.encode(observations)
        ranked = rerank_by_q(self.critic.q, features, relative)  # the global step
        k = min(self.top_k, n + 1)
        top_q, top = ranked.scores.topk(k, dim=1)  # (B, k)
        starts = relative[torch.arange(b)[:, None], top]  # (B, k, H, 10)
        optimised, final, reverted = self.ascend(
            features.repeat_interleave(k, dim=0), starts.flatten(0, 1), top_q.flatten()
        )
        best = final.view(b, k).argmax(dim=1)
        chosen = optimised.view(b, k, *optimised.shape[1:])[torch.arange(b), best]
        chosen_abs = absolute_pose10_torch(chosen, current)
        chosen_q, dataset_q = final.view(b, k)[torch.arange(b), best], ranked.scores[:, 0]
        return Relabelled(
            actions=chosen_abs,
            valid=torch.isfinite(chosen_abs).all(dim=(1, 2)) & (chosen_q > dataset_q),
            chosen_q=chosen_q,
            dataset_q=dataset_q,
            global_spread=ranked.scores.std(dim=1),
            dataset_won=ranked.index == 0,
            reverted=reverted.view(b, k),
            drift=chosen_abs[:, -1, :3] - dataset_chunks[:, -1, :3].float(),
        )


def diagnostics(parts: list[Relabelled]) -> dict[str, float]:
    """The paper's relabelling diagnostics over every relabelled frame."""
    cat = {
        name: torch.cat([getattr(p, name).float().flatten() for p in parts])
        for name in Relabelled.__annotations__
        if name != "drift"
    }
    drift = torch.cat([p.drift.float() for p in parts])
    return {
        "frames": int(sum(len(p.valid) for p in parts)),
        "valid_fraction": cat["valid"].mean().item(),
        "mean_chosen_q": cat["chosen_q"].mean().item(),
        "mean_dataset_q": cat["dataset_q"].mean().item(),
        "mean_global_q_spread": cat["global_spread"].mean().item(),
        "revert_rate": cat["reverted"].mean().item(),
        "dataset_action_wins": cat["dataset_won"].mean().item(),
        "mean_drift_mm": 1000.0 * drift.norm(dim=-1).mean().item(),
        # The paper's robot drifted upward: the signed mean per world axis shows such a bias.
        "mean_drift_xyz_mm": [round(1000.0 * v, 2) for v in drift.mean(dim=0).tolist()],
    }


class RelabelCache:
    """Optimised chunks by dataset frame index, with a validity mask; saved as one safetensors file."""

    def __init__(self, index: Tensor, actions: Tensor, valid: Tensor) -> None:
        if not (len(index) == len(actions) == len(valid)):
            raise ValueError(
                f"cache lengths differ: index {len(index)}, actions {len(actions)}, valid {len(valid)}"
            )
        order = index.long().argsort()
        self.index, self.actions, self.valid = (
            index.long()[order],
            actions.float()[order],
            valid.bool()[order],
        )
        if len(self.index) and (self.index[1:] == self.index[:-1]).any():
            raise ValueError("cache index holds a frame twice")

    def save(self, path: str | Path) -> None:
        """Write ``index``, ``action``, ``valid`` tensors."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        save_file({"index": self.index, "action": self.actions, "valid": self.valid}, str(path))

    @classmethod
    def load(cls, path: str | Path, field: str = "parl_cache_path") -> RelabelCache:
        """Read a file written by ``save``."""
        if not Path(path).is_file():
            raise FileNotFoundError(f"{field}={str(path)!r} is not a relabel cache file")
        tensors = load_file(str(path))
        return cls(tensors["index"], tensors["action"], tensors["valid"])

    def apply(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """A copy of the training batch whose action chunks are the cache's where a valid entry exists."""
        if INDEX not in batch:
            raise KeyError(
                f"a relabelled training batch needs LeRobotDataset's {INDEX!r}; it has {sorted(batch)}"
            )
        index = batch[INDEX].long().flatten().cpu()
        pos = torch.searchsorted(self.index, index).clamp(max=max(len(self.index) - 1, 0))
        use = (
            (self.index[pos] == index) & self.valid[pos]
            if len(self.index)
            else torch.zeros_like(index, dtype=torch.bool)
        )
        if not use.any():
            return batch
        action = batch[ACTION].clone()
        if action.shape[1:] != self.actions.shape[1:]:
            raise ValueError(
                f"cached chunks are {tuple(self.actions.shape[1:])}, the batch's {tuple(action.shape[1:])}"
            )
        action[use.to(action.device)] = self.actions[pos[use]].to(action)
        return {**batch, ACTION: action}
