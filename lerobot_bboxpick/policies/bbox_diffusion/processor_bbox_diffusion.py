"""Pre/post-processors of ``bbox_diffusion``: LeRobot's standard steps, saved with the checkpoint.

The policy speaks absolute TCP poses at its boundary, like every other part of the project: its
``forward`` takes the dataset's absolute action chunks and its ``select_action`` /
``predict_action_chunk`` return absolute actions. UMI's relative poses (``inv(T_base) @ T``) live
inside the model, which holds the observed pose they are relative to; so the processors need no
state of their own and the pipeline works unchanged under ``lerobot-eval``, ``lerobot-rollout``
(sync and RTC) and our suite.
"""

from typing import Any

import torch
from lerobot.processor import PolicyAction, PolicyProcessorPipeline
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines

from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig


def make_bbox_diffusion_pre_post_processors(
    config: BboxDiffusionConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """Rename -> batch -> device -> normalise (identity for this policy); unnormalise -> cpu."""
    s = make_default_policy_processor_steps(config, dataset_stats)
    return make_policy_processor_pipelines(
        input_steps=[s.rename_observations, s.add_batch_dim, s.to_device, s.normalize],
        output_steps=[s.unnormalize, s.to_cpu],
    )


# The paper type's processors are the same steps (LeRobot looks them up by type name).
make_bbox_diffusion_paper_pre_post_processors = make_bbox_diffusion_pre_post_processors
