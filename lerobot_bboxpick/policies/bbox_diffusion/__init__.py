"""The ``bbox_diffusion`` (and ``bbox_diffusion_paper``) policy: bbox-as-mask conditioned diffusion
(paper section 4.1).

Importing this registers its config with LeRobot and its own processor step (a checkpoint's saved
preprocessor names it, and LeRobot looks steps up in its registry when loading one); LeRobot imports the
sibling ``modeling_`` module by naming convention when it needs it."""

from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
    BboxDiffusionConfig,
    BboxDiffusionPaperConfig,
)
from lerobot_bboxpick.policies.bbox_diffusion.processor_bbox_diffusion import UnpackBboxFromStateStep

__all__ = ["BboxDiffusionConfig", "BboxDiffusionPaperConfig", "UnpackBboxFromStateStep"]
