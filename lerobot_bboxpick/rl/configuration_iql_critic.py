"""Configuration of the IQL critic over action chunks (paper section 5.3).

A plain draccus dataclass, saved as ``config.json`` beside ``model.safetensors`` like a LeRobot
checkpoint. It is deliberately not a registered ``PreTrainedConfig``: the critic is no policy, and
registering it would offer it to ``lerobot-train --policy.type``. The horizon, observation history and
action scaling are not options here: they are the ``bbox_diffusion`` policy's, whose encoder the critic
reuses (saved with the critic as ``encoder/config.json``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class IqlCriticConfig:
    """Options of the IQL critic model."""

    # Widths (paper: state -> 512, flattened 16 x 10 chunk -> 256 through a small MLP, heads 2 x 512).
    state_embed_dim: int = 512
    action_embed_dim: int = 256
    hidden_dim: int = 512
    num_hidden_layers: int = 2
    # IQL (paper: expectile 0.7, gamma 0.99, Polyak 0.005; ikostrikov's locomotion values).
    expectile: float = 0.7
    gamma: float = 0.99
    polyak: float = 0.005
    # The paper freezes the encoder warm-started from the policy, so the critic sees the policy's
    # features; unfrozen, it trains with the optimiser's encoder lr scale.
    freeze_encoder: bool = True

    def __post_init__(self) -> None:
        for name in ("state_embed_dim", "action_embed_dim", "hidden_dim", "num_hidden_layers"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}={value!r} must be an integer >= 1")
        if not 0.0 < self.expectile < 1.0:
            raise ValueError(f"expectile={self.expectile} must be in (0, 1)")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma={self.gamma} must be in (0, 1]")
        if not 0.0 < self.polyak <= 1.0:
            raise ValueError(f"polyak={self.polyak} must be in (0, 1]")
