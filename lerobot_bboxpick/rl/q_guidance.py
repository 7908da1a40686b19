"""Q-guided diffusion (paper section 4.2, item 2): the critic's action gradient steers each denoising step.

At every DDIM step the policy's UNet predicts the clean chunk ``x0`` (``prediction_type="sample"``);
the guide adds ``clamp(scale * dQ(s, x0)/dx0, -max_step, max_step)`` to it before the scheduler step.
The trust region is the bound: per denoising step no element of the (scaled) chunk moves more than
``max_step`` (the action scale is ``action_position_scale``, 0.15 m, so 0.02 is 3 mm of position), and
the UNet re-projects the corrected chunk toward its own distribution at the next step. A critic
whose Q is flat in the action (the paper's table 4) gives gradients near 0: the policy's own chunk.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import Tensor

from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import Guide


@dataclass
class QGuidance:
    """Bounded critic-gradient guidance for ``bbox_diffusion`` sampling.

    ``q_trace`` holds, for the latest guided sampling, the mean critic value of the predicted clean chunk
    at each denoising step (a diagnostic: it should rise).
    """

    critic: object  # an IqlCriticModel (encode, q)
    scale: float
    max_step: float
    q_trace: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.scale > 0:
            raise ValueError(f"guidance_scale={self.scale!r} must be > 0")
        if not 0 < self.max_step <= 1:
            raise ValueError(f"guidance_max_step={self.max_step!r} must be in (0, 1] (scaled action units)")

    def guide(
        self, policy, batch: dict[str, Tensor], repeats: int = 1, features: Tensor | None = None
    ) -> Guide:
        """The guide for sampling ``policy`` ``repeats`` times per observation of ``batch``
        ``(B, n_obs, ...)`` (samples ordered as ``repeat_interleave``); each observation is encoded once,
        or not at all when the caller passes the critic's ``features`` ``(B, D)`` of ``batch``."""
        with torch.no_grad():
            if features is None:
                features = self.critic.encode(batch)
            state = features.repeat_interleave(repeats, dim=0)
        scaler = policy.model.action_scaler  # fixed scales, the same in the EMA copy
        self.q_trace = []

        def guide(predicted: Tensor) -> Tensor:
            with torch.enable_grad(), torch.autocast(predicted.device.type, enabled=False):
                x = predicted.detach().float().requires_grad_(True)
                q = self.critic.q(state, scaler.inverse(x))
                (grad,) = torch.autograd.grad(q.sum(), x)
            self.q_trace.append(float(q.mean()))
            return (self.scale * grad).clamp(-self.max_step, self.max_step).to(predicted.dtype)

        return guide
