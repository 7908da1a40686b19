"""Progressive step distillation (Salimans & Ho 2022): a student that samples in half the DDIM steps.

The student (the policy being trained, sampling at ``num_inference_steps`` = n) learns, at each of the
timesteps it visits, to land in one deterministic DDIM step where a frozen teacher (``distill_teacher_path``,
the same architecture) lands in two steps of its own 2n-step schedule, from the same noisy chunk and
the same augmented observation. Training only imitates the teacher's sampler, so the student's n-step
chunks approach the teacher's 2n-step ones (half the UNet calls per chunk) instead of the coarser
integration that plain n-step sampling of the teacher gives.

``lerobot-train --policy.path=<teacher> --policy.distill_teacher_path=<teacher>
--policy.num_inference_steps=8`` runs one halving with LeRobot's own loop, optimiser, EMA and
checkpoints; the teacher is frozen and lives outside the policy's modules, so it is not saved with the
student.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from lerobot.utils.constants import ACTION
from torch import Tensor

from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
    INPUT_OUTPUT_FIELDS,
    BboxDiffusionConfig,
)
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionModel

FINAL = -1  # "after the last timestep": DDIM's final alpha (1 here: set_alpha_to_one)
# What the teacher must share with the student for its two steps to be a target for one of the student's.
MATCHING_FIELDS = INPUT_OUTPUT_FIELDS + (
    "num_train_timesteps",
    "beta_schedule",
    "prediction_type",
    "clip_sample",
    "clip_sample_range",
    "timestep_spacing",
)


@dataclass(frozen=True)
class StepPairs:
    """Per student step: its timestep, the teacher's intermediate one and where both land (FINAL: the
    clean chunk), as (n,) long tensors in the student's sampling order."""

    start: Tensor
    middle: Tensor
    end: Tensor


def step_pairs(student: BboxDiffusionModel, teacher: BboxDiffusionModel) -> StepPairs:
    """Match each student step with two of the teacher's steps (at twice the student's step count).

    Raises ValueError when the teacher's schedule does not pass through every student timestep (e.g.
    ``leading`` spacing of 50 at 7 and 14 steps: 42, 35, ... against 39, 36, ...)."""
    n = student.config.num_inference_steps
    visited = student.sampler_timesteps().tolist()
    teacher.noise_scheduler.set_timesteps(2 * n)
    teacher_visited = teacher.noise_scheduler.timesteps.tolist()
    teacher_next = dict(zip(teacher_visited, teacher_visited[1:] + [FINAL], strict=True))
    starts, middles, ends = [], [], []
    for start, end in zip(visited, visited[1:] + [FINAL], strict=True):
        middle = teacher_next.get(start)
        # The teacher reaches the end in two steps (or one, for the last step to the clean chunk).
        if middle is None or (middle != end and teacher_next.get(middle) != end):
            raise ValueError(
                f"num_inference_steps={n}: the teacher's {2 * n} {student.config.timestep_spacing} steps "
                f"{teacher_visited} do not pass through the student's {visited} two by two; with leading "
                f"spacing choose n so that num_train_timesteps // n is even (8 or 4 of 50)"
            )
        starts.append(start)
        middles.append(middle)
        ends.append(end)
    return StepPairs(*(torch.tensor(v, dtype=torch.long) for v in (starts, middles, ends)))


def _alpha(model: BboxDiffusionModel, timesteps: Tensor) -> Tensor:
    """DDIM's cumulative alpha at each timestep (B,), FINAL giving its final alpha; shaped (B, 1, 1)."""
    scheduler = model.noise_scheduler
    cumulative = scheduler.alphas_cumprod.to(timesteps.device)
    alpha = torch.where(
        timesteps >= 0,
        cumulative[timesteps.clamp(min=0)],
        torch.as_tensor(float(scheduler.final_alpha_cumprod), device=timesteps.device),
    )
    return alpha.float()[:, None, None]


def clean_and_noise(
    model: BboxDiffusionModel, output: Tensor, noisy: Tensor, timesteps: Tensor
) -> tuple[Tensor, Tensor]:
    """The clean chunk (clipped if the config clips) and the noise a UNet output implies, as diffusers'
    ``DDIMScheduler.step`` derives them (the noise from the unclipped clean chunk)."""
    c = model.config
    alpha = _alpha(model, timesteps)
    if c.prediction_type == "sample":
        clean = output
        noise = (noisy - alpha.sqrt() * clean) / (1 - alpha).sqrt()
    else:
        noise = output
        clean = (noisy - (1 - alpha).sqrt() * noise) / alpha.sqrt()
    if c.clip_sample:
        clean = clean.clamp(-c.clip_sample_range, c.clip_sample_range)
    return clean, noise


def ddim_step(model: BboxDiffusionModel, output: Tensor, noisy: Tensor, start: Tensor, end: Tensor) -> Tensor:
    """One deterministic DDIM step (eta = 0) per sample, from timestep ``start`` to ``end`` (B,): what
    ``DDIMScheduler.step`` computes for one shared timestep, batched over differing ones."""
    clean, noise = clean_and_noise(model, output, noisy, start)
    alpha_end = _alpha(model, end)
    return alpha_end.sqrt() * clean + (1 - alpha_end).sqrt() * noise


def one_step_target(
    model: BboxDiffusionModel, noisy: Tensor, landed: Tensor, start: Tensor, end: Tensor
) -> Tensor:
    """The UNet output with which one DDIM step from ``noisy`` at ``start`` lands on ``landed`` at
    ``end`` (the inverse of ``ddim_step``, before clipping), in the model's prediction type."""
    alpha_start, alpha_end = _alpha(model, start), _alpha(model, end)
    # landed = sqrt(a_e) x0 + sqrt(1 - a_e) (noisy - sqrt(a_s) x0) / sqrt(1 - a_s), solved for x0.
    ratio = ((1 - alpha_end) / (1 - alpha_start)).sqrt()
    clean = (landed - ratio * noisy) / (alpha_end.sqrt() - ratio * alpha_start.sqrt())
    c = model.config
    if c.clip_sample:  # the student's clean chunk is clipped before it is used: aim inside the range
        clean = clean.clamp(-c.clip_sample_range, c.clip_sample_range)
    if c.prediction_type == "sample":
        return clean
    return (noisy - alpha_start.sqrt() * clean) / (1 - alpha_start).sqrt()


class StepDistillationLoss:
    """MSE between the student's UNet output and the output whose one DDIM step lands where the frozen
    teacher's two steps land, at a student timestep drawn uniformly per sample."""

    def __init__(self, teacher: BboxDiffusionModel) -> None:
        # Train mode: its augmentation must replay the student's random crop (see
        # ``BboxDiffusionModel.conditioned_chunk``); no gradient ever reaches it.
        self.teacher = teacher.train().requires_grad_(False)
        self._pairs: StepPairs | None = None

    @classmethod
    def from_config(cls, config: BboxDiffusionConfig) -> StepDistillationLoss:
        """The loss with the teacher at ``config.distill_teacher_path`` (its EMA weights when it has them)."""
        from lerobot_bboxpick.rl.advantage_weighting import check_config_matches, require_checkpoint_dir
        from lerobot_bboxpick.rl.modeling_iql_critic import load_policy  # rl imports the policy

        policy = load_policy(require_checkpoint_dir(config.distill_teacher_path, "distill_teacher_path"))
        teacher = policy.ema_model if policy.ema_model is not None else policy.model
        check_config_matches(teacher.config, config, "distill_teacher_path", MATCHING_FIELDS)
        return cls(teacher)

    def __call__(self, model: BboxDiffusionModel, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        """The loss of one training batch and its diagnostics (plain floats, logged by lerobot-train)."""
        if self._pairs is None:
            self._pairs = step_pairs(model, self.teacher)
        self.teacher.to(batch[ACTION].device)
        cond, trajectory, teacher_cond = model.conditioned_chunk(batch, self.teacher)
        device = trajectory.device
        pick = torch.randint(0, len(self._pairs.start), (trajectory.shape[0],), device=device)
        start, middle, end = (
            t.to(device)[pick] for t in (self._pairs.start, self._pairs.middle, self._pairs.end)
        )
        noisy = model.noise_scheduler.add_noise(trajectory, torch.randn_like(trajectory), start)
        with torch.no_grad():
            halfway = ddim_step(
                self.teacher, self.teacher.unet(noisy, start, global_cond=teacher_cond), noisy, start, middle
            )
            # The last student step (to the clean chunk) is one teacher step: ``middle`` is FINAL there.
            second = self.teacher.unet(halfway, middle.clamp(min=0), global_cond=teacher_cond)
            landed = torch.where(
                (middle == FINAL)[:, None, None],
                halfway,
                ddim_step(self.teacher, second, halfway, middle, end),
            )
            target = one_step_target(model, noisy, landed, start, end)
        prediction = model.unet(noisy, start, global_cond=cond)
        loss = F.mse_loss(prediction, target)
        # Its root, in scaled chunk units: lerobot-train logs three decimals, and the loss is ~1e-4.
        return loss, {"distill_rms": loss.sqrt().item()}
