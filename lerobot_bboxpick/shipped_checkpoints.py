"""The trained checkpoints that ship under ``examples/`` (paths relative to the repository root).

``SHIPPED_CHECKPOINT`` is the one the README, the main job and the dashboard offer; its model card is the
``README.md`` beside it. ``FIRST_SHIPPED_CHECKPOINT`` (no height input) is the imitation policy that
docs/counterfactual, docs/dagger and the sampler study measured: it stays so that their commands reproduce.
"""

from pathlib import Path

SHIPPED_CHECKPOINT = Path("examples/bbox_diffusion_lego_pick_height")
FIRST_SHIPPED_CHECKPOINT = Path("examples/bbox_diffusion_lego_pick")
