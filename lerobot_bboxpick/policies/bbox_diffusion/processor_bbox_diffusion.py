"""Pre/post-processors of ``bbox_diffusion``: LeRobot's standard steps plus UMI's SE(3) relative actions.

* ``RelativePoseActionStep`` (preprocessor) makes the action chunk relative to the latest observed
  TCP pose, ``inv(T_base) @ T`` (UMI), and remembers that base pose.
* ``AbsolutePoseActionStep`` (postprocessor) maps the policy's relative actions back to absolute
  poses, ``T_base @ T_rel``, with the base pose its paired preprocessor step saw last.

The pair shares the base pose through a slot keyed by ``pair_id`` (a random id saved in both JSON
configs), so the link survives ``save_pretrained``/``from_pretrained`` without code in the loader.
Observation poses are made relative inside the policy, which holds the observation history (LeRobot's
eval only resets the policy between episodes, not the processors).
"""

import uuid
from dataclasses import dataclass, field
from typing import Any

import torch
from lerobot.configs import PipelineFeatureType, PolicyFeature
from lerobot.lerobot_types import EnvTransition, TransitionKey
from lerobot.processor import (
    PolicyAction,
    PolicyProcessorPipeline,
    ProcessorStep,
    ProcessorStepRegistry,
)
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines
from lerobot.utils.constants import OBS_STATE

from lerobot_bboxpick.geometry import absolute_pose9_torch, relative_pose9_torch
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig

# pair_id -> latest observed pose10 (B, 10) seen by the preprocessor
_BASE_POSES: dict[str, torch.Tensor] = {}


def relative_pose10_torch(poses: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """``inv(T_base) @ T`` on the pose9 part of (..., T, 10) poses, base (..., 10); width kept absolute."""
    rel9 = relative_pose9_torch(poses[..., :9], base[..., None, :9])
    return torch.cat([rel9, poses[..., 9:]], dim=-1)


def absolute_pose10_torch(rel: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """``T_base @ T_rel`` on (..., T, 10) relative poses, base (..., 10); width kept absolute."""
    abs9 = absolute_pose9_torch(rel[..., :9], base[..., None, :9])
    return torch.cat([abs9, rel[..., 9:]], dim=-1)


def _chunked(action: torch.Tensor, fn) -> torch.Tensor:
    """Apply ``fn`` to a (B, T, 10) chunk; a single (B, 10) action goes through as a chunk of one."""
    return fn(action) if action.ndim == 3 else fn(action[:, None])[:, 0]


@dataclass
class _PairedPoseStep(ProcessorStep):
    """A step of the relative/absolute pair; ``pair_id`` links the two (saved in the JSON config)."""

    pair_id: str = ""

    def get_config(self) -> dict[str, Any]:
        """Serialised with the checkpoint."""
        return {"pair_id": self.pair_id}

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        """Shapes are unchanged."""
        return features


@ProcessorStepRegistry.register("bbox_diffusion_relative_pose")
@dataclass
class RelativePoseActionStep(_PairedPoseStep):
    """Action chunk -> relative to the latest observed pose; remembers that pose for the postprocessor."""

    pair_id: str = field(default_factory=lambda: uuid.uuid4().hex)

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        observation = transition.get(TransitionKey.OBSERVATION) or {}
        state = observation.get(OBS_STATE)
        if state is None:
            return transition
        base = state[:, -1] if state.ndim == 3 else state  # training batches carry (B, n_obs, 10)
        _BASE_POSES[self.pair_id] = base.detach()
        action = transition.get(TransitionKey.ACTION)
        if action is None:
            return transition
        new = transition.copy()
        new[TransitionKey.ACTION] = _chunked(action.to(base.dtype), lambda c: relative_pose10_torch(c, base))
        return new


@ProcessorStepRegistry.register("bbox_diffusion_absolute_pose")
@dataclass
class AbsolutePoseActionStep(_PairedPoseStep):
    """Relative action(s) -> absolute TCP poses, using the pose its paired preprocessor step saw last."""

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        action = transition.get(TransitionKey.ACTION)
        if action is None:
            return transition
        base = _BASE_POSES.get(self.pair_id)
        if base is None:
            raise RuntimeError(
                f"no observed pose for pair_id={self.pair_id!r}: run the policy's preprocessor on an "
                "observation (with observation.state) before its postprocessor"
            )
        new = transition.copy()
        base = base.to(action.device, action.dtype)
        new[TransitionKey.ACTION] = _chunked(action, lambda c: absolute_pose10_torch(c, base))
        return new


def make_bbox_diffusion_pre_post_processors(
    config: BboxDiffusionConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """Rename -> batch -> device -> normalise (identity for this policy) -> relative actions;
    absolute actions -> cpu."""
    s = make_default_policy_processor_steps(config, dataset_stats)
    relative = RelativePoseActionStep()
    absolute = AbsolutePoseActionStep(pair_id=relative.pair_id)
    return make_policy_processor_pipelines(
        input_steps=[s.rename_observations, s.add_batch_dim, s.to_device, s.normalize, relative],
        output_steps=[s.unnormalize, absolute, s.to_cpu],
    )
