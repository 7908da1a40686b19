"""The ``bbox_diffusion`` policy: bbox-as-mask conditioned diffusion (paper section 4.1).

Importing this registers its config with LeRobot; LeRobot imports the sibling ``modeling_``/``processor_``
modules by naming convention when it needs them."""

from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig

__all__ = ["BboxDiffusionConfig"]
