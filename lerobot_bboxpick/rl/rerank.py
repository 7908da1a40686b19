"""Q-reranking (paper section 4.2, item 1; IDQL's "sample N, keep argmax Q"): score candidate action
chunks with the critic and keep the best one per state.

``rerank_by_q`` is the core on state features and relative chunks; ``rerank_absolute`` takes the
policy's absolute chunks and an observation batch; ``sample_and_rerank`` draws the candidates from a
``bbox_diffusion`` policy; ``QRerankSelector`` plugs that into the policy's ``select_action`` (what
``bboxpick-suite --critic_path=... --rerank_samples=N`` runs).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from lerobot_bboxpick.geometry import relative_pose10_torch
from lerobot_bboxpick.keys import STATE
from lerobot_bboxpick.rl.q_guidance import QGuidance


@dataclass
class RerankResult:
    """The chosen chunk per state, its index among the candidates, and every candidate's score."""

    best: Tensor  # (B, H, A)
    index: Tensor  # (B,) long
    scores: Tensor  # (B, N)


@torch.no_grad()
def rerank_by_q(q_fn: Callable[[Tensor, Tensor], Tensor], state: Tensor, candidates: Tensor) -> RerankResult:
    """Argmax-Q candidate per state.

    Args:
        q_fn: ``(states (M, D), chunks (M, H, A)) -> (M,)`` scores, e.g. ``IqlCriticModel.q``.
        state: ``(B, D)`` state features.
        candidates: ``(B, N, H, A)`` chunks in ``q_fn``'s action space (relative chunks for the critic).
    """
    if candidates.ndim != 4 or state.ndim != 2 or candidates.shape[0] != state.shape[0]:
        raise ValueError(
            f"expected state (B, D) and candidates (B, N, H, A) with the same B, got "
            f"{tuple(state.shape)} and {tuple(candidates.shape)}"
        )
    b, n = candidates.shape[:2]
    scores = q_fn(state.repeat_interleave(n, dim=0), candidates.flatten(0, 1)).view(b, n)
    index = scores.argmax(dim=1)
    return RerankResult(best=candidates[torch.arange(b), index], index=index, scores=scores)


@torch.no_grad()
def rerank_absolute(
    critic, batch: dict[str, Tensor], candidates: Tensor, features: Tensor | None = None
) -> RerankResult:
    """Rerank absolute chunks ``(B, N, H, 10)`` (what the policy returns) for observations ``batch``
    (``(B, n_obs, ...)``, the policy's input); ``best`` is absolute too.

    The observation is encoded once per state, not once per candidate (not at all when the caller
    passes the critic's ``features`` ``(B, D)`` of ``batch``).
    """
    state = critic.encode(batch) if features is None else features
    current = batch[STATE][:, -1]  # the pose the critic's chunks are relative to
    relative = relative_pose10_torch(candidates.float(), current[:, None].float())
    result = rerank_by_q(critic.q, state, relative)
    result.best = candidates[torch.arange(len(candidates)), result.index]
    return result


@torch.no_grad()
def sample_chunks(
    policy,
    batch: dict[str, Tensor],
    n: int,
    generator: torch.Generator | None = None,
    guidance: QGuidance | None = None,
    features: Tensor | None = None,
) -> Tensor:
    """``n`` absolute chunks ``(B, n, H, 10)`` per observation of ``batch``, drawn from
    ``policy.predict_action_chunk`` in one batch (each steered by ``guidance`` when given; ``features``:
    the guidance critic's encoding of ``batch`` if the caller has it)."""
    if n < 1:
        raise ValueError(f"n={n} must be >= 1")
    b = batch[STATE].shape[0]
    repeated = {k: v.repeat_interleave(n, dim=0) for k, v in batch.items() if isinstance(v, Tensor)}
    guide = guidance.guide(policy, batch, n, features) if guidance is not None else None
    chunks = policy.predict_action_chunk(repeated, generator=generator, guide=guide)
    return chunks.view(b, n, *chunks.shape[1:])


@torch.no_grad()
def sample_and_rerank(
    policy, critic, batch: dict[str, Tensor], n: int, generator: torch.Generator | None = None
) -> RerankResult:
    """Draw ``n`` chunks per observation from ``policy.predict_action_chunk`` and keep the argmax-Q one."""
    return rerank_absolute(critic, batch, sample_chunks(policy, batch, n, generator))


class QRerankSelector:
    """A ``bbox_diffusion`` chunk selector (``policy.chunk_selector``): sample ``n`` chunks from the
    policy (Q-guided when ``guidance`` is given: ``rl.q_guidance``), optionally add bounded per-axis
    residuals of each (``perturbations``, ramped in over the chunk: ``rl.chunk_perturbations``), and
    execute the argmax-Q candidate (with ``n=1`` and no residuals: the guided draw itself).

    The trust region is the policy's own distribution, widened by at most the residuals' size: every
    executed chunk is one the imitation policy could have drawn itself, or such a chunk moved by a few
    centimetres or degrees at its end, so the critic only ranks candidates near the data it was trained
    on (``bboxpick-counterfactual`` tries exactly these residuals), never ones far from it.
    """

    def __init__(
        self, critic, n: int, perturbations: Sequence = (), guidance: QGuidance | None = None
    ) -> None:
        if n < 1:
            raise ValueError(f"rerank samples n={n} must be >= 1")
        self.critic, self.n, self.perturbations = critic, n, tuple(perturbations)
        if guidance is not None and guidance.critic is not critic:
            raise ValueError("QRerankSelector: guidance must use the selector's own critic")
        self.guidance = guidance
        self.last: RerankResult | None = None  # the latest choice, for diagnostics

    @property
    def candidates_per_state(self) -> int:
        """Draws times (1 + residuals)."""
        return self.n * (1 + len(self.perturbations))

    def _with_residuals(self, draws: Tensor) -> Tensor:
        """(B, n, H, 10) draws -> (B, n * (1 + P), H, 10): each draw, then its residuals."""
        if not self.perturbations:
            return draws
        arr = draws.double().cpu().numpy()
        out = [[d] + [p.apply(d) for p in self.perturbations] for row in arr for d in row]
        stacked = torch.from_numpy(np.asarray(out)).to(draws.dtype)
        return stacked.view(draws.shape[0], self.candidates_per_state, *draws.shape[2:])

    def __call__(self, policy, stacked: dict[str, Tensor], generator: torch.Generator | None) -> Tensor:
        """The chosen absolute chunk ``(B, H, 10)`` for observations ``stacked``."""
        # One encoding of the observations serves the guide and the ranking (the same critic).
        with torch.no_grad():
            features = self.critic.encode(stacked)
        draws = sample_chunks(policy, stacked, self.n, generator, self.guidance, features)
        candidates = self._with_residuals(draws)
        self.last = rerank_absolute(self.critic, stacked, candidates, features)
        return self.last.best
