"""The ``bbox_diffusion`` (and ``bbox_diffusion_paper``) policy: bbox-as-mask conditioned diffusion
(paper section 4.1).

Importing this registers its config with LeRobot; LeRobot imports the sibling ``modeling_``/``processor_``
modules by naming convention when it needs them."""

from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
    BboxDiffusionConfig,
    BboxDiffusionPaperConfig,
)

__all__ = ["BboxDiffusionConfig", "BboxDiffusionPaperConfig"]
