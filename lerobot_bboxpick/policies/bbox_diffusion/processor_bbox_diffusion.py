"""Pre/post-processors of ``bbox_diffusion``: LeRobot's standard steps, saved with the checkpoint.

The policy speaks absolute TCP poses at its boundary, like every other part of the project: its
``forward`` takes the dataset's absolute action chunks and its ``select_action`` /
``predict_action_chunk`` return absolute actions. UMI's relative poses (``inv(T_base) @ T``) live
inside the model, which holds the observed pose they are relative to; so the processors need no
state of their own and the pipeline works unchanged under ``lerobot-eval``, ``lerobot-rollout``
(sync and RTC) and our suite.

One step of our own, ``UnpackBboxFromStateStep``: LeRobot's robot CLIs (``lerobot-record``,
``lerobot-rollout``) pack every scalar a robot reports into one ``observation.state``; the ``ur5`` robot
reports pose10 then the target box, so a 14-float state is split back into ``observation.state`` (10)
and ``observation.bbox`` (4) before the policy sees it.
"""

from dataclasses import dataclass
from typing import Any

import torch
from lerobot.configs import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.processor import (
    ObservationProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    ProcessorStepRegistry,
)
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines

from lerobot_bboxpick.keys import BBOX, STATE
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
    PACKED_STATE_DIM,
    POSE_DIM,
    BboxDiffusionConfig,
)


@ProcessorStepRegistry.register(name="bboxpick_unpack_bbox_from_state")
@dataclass
class UnpackBboxFromStateStep(ObservationProcessorStep):
    """A packed ``observation.state`` (..., 14) = pose10 + bbox4 -> ``observation.state`` (..., 10) and
    ``observation.bbox`` (..., 4); any other observation passes unchanged."""

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Split a packed state; a separate ``observation.bbox`` (the env's and the datasets') wins."""
        state = observation.get(STATE)
        if state is None or BBOX in observation or state.shape[-1] != PACKED_STATE_DIM:
            return observation
        observation[STATE] = state[..., :POSE_DIM]
        observation[BBOX] = state[..., POSE_DIM:]
        return observation

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        """A (14,) state feature becomes a (10,) state and a (4,) bbox."""
        obs = features.get(PipelineFeatureType.OBSERVATION, {})
        state = obs.get(STATE)
        if state is not None and BBOX not in obs and state.shape == (PACKED_STATE_DIM,):
            obs[STATE] = PolicyFeature(type=FeatureType.STATE, shape=(POSE_DIM,))
            obs[BBOX] = PolicyFeature(type=FeatureType.STATE, shape=(PACKED_STATE_DIM - POSE_DIM,))
        return features


def make_bbox_diffusion_pre_post_processors(
    config: BboxDiffusionConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """Rename -> batch -> device -> unpack a robot's packed state -> normalise (identity for this
    policy); unnormalise -> cpu."""
    s = make_default_policy_processor_steps(config, dataset_stats)
    return make_policy_processor_pipelines(
        input_steps=[
            s.rename_observations,
            s.add_batch_dim,
            s.to_device,
            UnpackBboxFromStateStep(),
            s.normalize,
        ],
        output_steps=[s.unnormalize, s.to_cpu],
    )


# The paper type's processors are the same steps (LeRobot looks them up by type name).
make_bbox_diffusion_paper_pre_post_processors = make_bbox_diffusion_pre_post_processors
