"""Advantage-weighted diffusion fine-tuning with a BC term and an anchor (paper section 6.2).

The paper weights each chunk's denoising loss by ``exp(A(s, a) / lambda)``, ``A = Q - V`` of a frozen
IQL critic, and, because that alone drifted, adds an unweighted BC term and an MSE anchor to a frozen
BC reference policy. Here it is a loss of the ``bbox_diffusion`` policy, switched on by its config
(``awr_critic_path``, ``anchor_policy_path``: see ``BboxDiffusionConfig``), so ``lerobot-train
--policy.path=<IL checkpoint> --policy.awr_critic_path=<critic>`` fine-tunes with LeRobot's own
training loop, optimiser, checkpoints and logs. The critic and the reference are frozen and live
outside the policy's modules: they are not saved with the fine-tuned checkpoint.

Instead of a critic, ``awr_advantages_path`` gives each training episode a measured advantage
(``rl.branch_advantages``: counterfactual successes' Monte-Carlo ``G - V``), looked up by the batch's
``episode_index``.

Weights are clipped at ``awr_max_weight`` (AWR's usual guard against a few chunks taking the whole
batch); the logged ``awr_clipped`` fraction says how often it binds.
"""

from __future__ import annotations

from pathlib import Path

import torch
from lerobot.utils.constants import ACTION
from torch import Tensor

from lerobot_bboxpick.geometry import relative_pose10_torch
from lerobot_bboxpick.keys import STATE
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
    INPUT_OUTPUT_FIELDS,
    BboxDiffusionConfig,
)
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionModel
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel, load_policy


class AdvantageWeightedLoss:
    """The fine-tuning objective: ``mean(w * l) + bc_weight * mean(l) + anchor_weight * mean((p - p_ref)^2)``
    with ``l`` the per-chunk denoising loss, ``w = min(exp(A / temperature), max_weight)`` (1 without a
    critic) and ``p`` / ``p_ref`` this model's and the reference's denoised predictions of one draw."""

    def __init__(
        self,
        critic: IqlCriticModel | None,
        reference: BboxDiffusionModel | None,
        temperature: float = 1.0,
        max_weight: float = 20.0,
        bc_weight: float = 1.0,
        anchor_weight: float = 0.5,
        episode_advantages: Tensor | None = None,
    ) -> None:
        """``critic``: any object with ``encode(observations)``, ``q(state, relative_chunk)`` and ``v(state)``
        (an ``IqlCriticModel``); ``reference``: a model of the trained policy's architecture;
        ``episode_advantages``: (episodes,) advantages by episode index, used instead of a critic."""
        if critic is not None and episode_advantages is not None:
            raise ValueError("give a critic or episode advantages, not both")
        self.critic = critic.eval().requires_grad_(False) if critic is not None else None
        self.episode_advantages = episode_advantages
        if reference is not None:
            # Train mode: its augmentation must replay the trained model's random crop (see
            # ``BboxDiffusionModel.denoising_terms``); no gradient ever reaches it.
            reference = reference.train().requires_grad_(False)
        self.reference = reference
        self.temperature = temperature
        self.max_weight = max_weight
        self.bc_weight = bc_weight
        self.anchor_weight = anchor_weight

    @classmethod
    def from_config(cls, config: BboxDiffusionConfig) -> AdvantageWeightedLoss | None:
        """The objective the config asks for, loading its critic and reference; None when neither is set."""
        if not config.advantage_weighted:
            return None
        critic = reference = episode_advantages = None
        if config.awr_advantages_path is not None:
            from lerobot_bboxpick.rl.branch_advantages import load_advantages

            episode_advantages = torch.from_numpy(load_advantages(config.awr_advantages_path))
        if config.awr_critic_path is not None:
            critic = IqlCriticModel.from_pretrained(
                require_checkpoint_dir(config.awr_critic_path, "awr_critic_path")
            )
            check_config_matches(critic.encoder.config, config, "awr_critic_path", ("horizon", "n_obs_steps"))
        if config.anchor_policy_path is not None:
            policy = load_policy(require_checkpoint_dir(config.anchor_policy_path, "anchor_policy_path"))
            reference = policy.ema_model if policy.ema_model is not None else policy.model
            check_config_matches(reference.config, config, "anchor_policy_path", INPUT_OUTPUT_FIELDS)
        return cls(
            critic,
            reference,
            temperature=config.awr_temperature,
            max_weight=config.awr_max_weight,
            bc_weight=config.awr_bc_weight,
            anchor_weight=config.anchor_weight,
            episode_advantages=episode_advantages,
        )

    @torch.no_grad()
    def advantages(self, model: BboxDiffusionModel, batch: dict[str, Tensor]) -> Tensor:
        """``Q(s, a) - V(s)`` (B,) of the batch's chunks under the frozen critic, or their episodes'
        measured advantages."""
        if self.episode_advantages is not None:
            return self._episode_lookup(batch)
        images, states, bboxes = model._inputs(batch)
        observations = {model.config.image_key: images, STATE: states}
        if bboxes is not None:
            observations[model.config.bbox_feature_key] = bboxes
        features = self.critic.encode(observations)
        relative = relative_pose10_torch(batch[ACTION].float(), states[:, -1].float())
        return self.critic.q(features, relative) - self.critic.v(features)

    def _episode_lookup(self, batch: dict[str, Tensor]) -> Tensor:
        if "episode_index" not in batch:
            raise KeyError("awr_advantages_path needs the batch's episode_index (a LeRobotDataset batch)")
        index = torch.as_tensor(batch["episode_index"]).long().reshape(-1).cpu()
        table = self.episode_advantages
        if int(index.max()) >= len(table) or int(index.min()) < 0:
            raise ValueError(
                f"awr_advantages_path has advantages for {len(table)} episodes; the batch holds episode "
                f"{int(index.max())}: it was written for another dataset (bboxpick-branch-advantages)"
            )
        return table[index].to(batch[ACTION].device)

    def weights(self, advantages: Tensor) -> Tensor:
        """``min(exp(A / temperature), max_weight)``."""
        return torch.exp(advantages / self.temperature).clamp(max=self.max_weight)

    def __call__(self, model: BboxDiffusionModel, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        """The loss of one training batch and its diagnostics (plain floats, logged by lerobot-train)."""
        device = batch[ACTION].device
        for frozen in (self.critic, self.reference):
            if frozen is not None:
                frozen.to(device)
        terms = model.denoising_terms(batch, reference=self.reference)
        info = {"diffusion_loss": terms.loss.mean().item()}
        if self.critic is not None or self.episode_advantages is not None:
            advantages = self.advantages(model, batch)
            weights = self.weights(advantages)
            info |= {
                "awr_advantage": advantages.mean().item(),
                "awr_weight": weights.mean().item(),
                "awr_clipped": (weights >= self.max_weight).float().mean().item(),
            }
        else:
            weights = torch.ones_like(terms.loss)
        loss = (weights * terms.loss).mean() + self.bc_weight * terms.loss.mean()
        if terms.reference_prediction is not None:
            anchor = (terms.prediction - terms.reference_prediction).pow(2).mean()
            info["anchor_mse"] = anchor.item()
            loss = loss + self.anchor_weight * anchor
        return loss, info


def require_checkpoint_dir(path: str, field: str) -> Path:
    """``path`` as a Path, or FileNotFoundError naming the config ``field`` when it is no folder."""
    if not Path(path).is_dir():
        raise FileNotFoundError(f"{field}={path!r} is not a checkpoint folder")
    return Path(path)


def check_config_matches(
    theirs: BboxDiffusionConfig, ours: BboxDiffusionConfig, field: str, names: tuple[str, ...]
) -> None:
    """The critic's / reference's observation and chunk layout must be the trained policy's."""
    wrong = {
        n: (getattr(theirs, n), getattr(ours, n)) for n in names if getattr(theirs, n) != getattr(ours, n)
    }
    if wrong:
        detail = ", ".join(f"{n}: {a!r} there, {b!r} here" for n, (a, b) in wrong.items())
        raise ValueError(f"{field} was built for another policy layout ({detail})")
