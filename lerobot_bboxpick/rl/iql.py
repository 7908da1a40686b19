"""Implicit Q-Learning (Kostrikov et al. 2021) over flattened action chunks, as pure functions + a module.

The objective (paper section 5.3; ikostrikov/implicit_q_learning ``critic.py``):

* value: expectile regression of ``V(s)`` toward ``min(Q1_target, Q2_target)(s, a)`` on dataset actions,
  ``L_V = E[|tau - 1(u < 0)| u^2]`` with ``u = Q_target(s, a) - V(s)``; ``tau = 0.7`` pushes V toward
  the upper expectile of Q over the behaviour actions without querying actions outside the data;
* Q: ``L_Q = sum_i E[(Q_i(s, a) - y)^2]`` with ``y = r + discount * (1 - done) * V(s')``;
* target Qs follow the online Qs by Polyak averaging (rate 0.005).

Here an "action" is a whole chunk (Q-chunking): ``reward`` is the (discounted) reward collected while
the chunk runs and ``discount`` the factor to the next chunk's state, both supplied by the data.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor, nn


# --------------------------------------------------------------------------- pure functions
def expectile_loss(diff: Tensor, tau: float) -> Tensor:
    """Asymmetric squared loss ``mean(|tau - 1(diff < 0)| * diff^2)``; minimised by the tau-expectile."""
    if not 0.0 < tau < 1.0:
        raise ValueError(f"expectile tau={tau} must be in (0, 1)")
    weight = torch.where(diff > 0, tau, 1.0 - tau)
    return (weight * diff.square()).mean()


def td_target(reward: Tensor, done: Tensor, discount: Tensor | float, next_v: Tensor) -> Tensor:
    """``r + discount * (1 - done) * V(s')``, with no gradient through ``V(s')``."""
    return reward + discount * (1.0 - done.to(reward.dtype)) * next_v.detach()


def value_loss(v: Tensor, q_target: Tensor, tau: float) -> Tensor:
    """IQL value loss: expectile regression of ``v`` toward the (detached) target-network Q."""
    return expectile_loss(q_target.detach() - v, tau)


def q_loss(q1: Tensor, q2: Tensor, target: Tensor) -> Tensor:
    """Sum of both Q heads' mean squared TD errors toward the (detached) target."""
    target = target.detach()
    return (q1 - target).square().mean() + (q2 - target).square().mean()


@torch.no_grad()
def polyak_update(target: nn.Module, source: nn.Module, rate: float) -> None:
    """``target <- (1 - rate) * target + rate * source``, parameter by parameter (in place)."""
    if not 0.0 < rate <= 1.0:
        raise ValueError(f"polyak rate={rate} must be in (0, 1]")
    for t, s in zip(target.parameters(), source.parameters(), strict=True):
        t.lerp_(s, rate)


def mlp(in_dim: int, hidden: Sequence[int], out_dim: int) -> nn.Sequential:
    """``Linear -> ReLU`` for each hidden width, then a final ``Linear`` to ``out_dim``."""
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(in_dim, width), nn.ReLU()]
        in_dim = width
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


# --------------------------------------------------------------------------- networks
@dataclass(frozen=True)
class IqlDims:
    """Widths of the critic (paper section 5.3: state -> 512, action chunk -> 256, heads 2 x 512)."""

    state_dim: int
    action_dim: int
    state_embed_dim: int = 512
    action_embed_dim: int = 256
    hidden_dim: int = 512
    num_hidden_layers: int = 2

    def __post_init__(self) -> None:
        for name in ("state_dim", "action_dim", "state_embed_dim", "action_embed_dim", "hidden_dim"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 1")
        if self.num_hidden_layers < 1:
            raise ValueError(f"num_hidden_layers={self.num_hidden_layers} must be >= 1")

    @property
    def hidden(self) -> tuple[int, ...]:
        """Hidden widths of a V or Q head."""
        return (self.hidden_dim,) * self.num_hidden_layers


class StateProjection(nn.Sequential):
    """State features -> ``state_embed_dim`` (Linear, LayerNorm, ReLU)."""

    def __init__(self, dims: IqlDims) -> None:
        width = dims.state_embed_dim
        super().__init__(nn.Linear(dims.state_dim, width), nn.LayerNorm(width), nn.ReLU())


class ValueNetwork(nn.Module):
    """``V(s)``: its own state projection and a two-layer head."""

    def __init__(self, dims: IqlDims) -> None:
        super().__init__()
        self.state_proj = StateProjection(dims)
        self.head = mlp(dims.state_embed_dim, dims.hidden, 1)

    def forward(self, state: Tensor) -> Tensor:
        """(B, state_dim) -> (B,)."""
        return self.head(self.state_proj(state)).squeeze(-1)


class TwinQNetwork(nn.Module):
    """``Q1(s, a), Q2(s, a)``: state projection, action-chunk MLP (flat chunk -> 256), two heads."""

    def __init__(self, dims: IqlDims) -> None:
        super().__init__()
        self.state_proj = StateProjection(dims)
        self.action_proj = nn.Sequential(
            mlp(dims.action_dim, (dims.action_embed_dim,), dims.action_embed_dim), nn.ReLU()
        )
        joint = dims.state_embed_dim + dims.action_embed_dim
        self.q1 = mlp(joint, dims.hidden, 1)
        self.q2 = mlp(joint, dims.hidden, 1)

    def forward(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor]:
        """(B, state_dim), (B, action_dim) -> (Q1 (B,), Q2 (B,)); ``action`` may also be (B, ..., k)."""
        x = torch.cat([self.state_proj(state), self.action_proj(action.flatten(1))], dim=-1)
        return self.q1(x).squeeze(-1), self.q2(x).squeeze(-1)


@dataclass
class IqlBatch:
    """One batch of chunk transitions in the critic's input space (features, flattened chunks)."""

    state: Tensor  # (B, state_dim)
    action: Tensor  # (B, action_dim)
    reward: Tensor  # (B,) reward collected while the chunk runs
    done: Tensor  # (B,) the episode ended within the chunk
    discount: Tensor  # (B,) discount to the next state (e.g. gamma ** chunk stride)
    next_state: Tensor  # (B, state_dim); ignored where done


class IqlCritic(nn.Module):
    """V(s), twin Q(s, a) (min of the two), and Polyak-averaged target Qs."""

    def __init__(self, dims: IqlDims) -> None:
        super().__init__()
        self.dims = dims
        self.value = ValueNetwork(dims)
        self.q = TwinQNetwork(dims)
        self.q_target = copy.deepcopy(self.q).requires_grad_(False)

    def v(self, state: Tensor) -> Tensor:
        """``V(s)``: (B,)."""
        return self.value(state)

    def q_min(self, state: Tensor, action: Tensor) -> Tensor:
        """``min(Q1, Q2)(s, a)`` of the online networks: (B,)."""
        return torch.minimum(*self.q(state, action))

    def q_target_min(self, state: Tensor, action: Tensor) -> Tensor:
        """``min(Q1, Q2)(s, a)`` of the target networks: (B,)."""
        return torch.minimum(*self.q_target(state, action))

    def losses(self, batch: IqlBatch, tau: float) -> tuple[Tensor, dict[str, float]]:
        """Value loss + Q loss of one batch, and scalars to log."""
        v = self.v(batch.state)
        with torch.no_grad():
            q_t = self.q_target_min(batch.state, batch.action)
            next_v = self.v(batch.next_state)
        l_v = value_loss(v, q_t, tau)
        target = td_target(batch.reward, batch.done, batch.discount, next_v)
        q1, q2 = self.q(batch.state, batch.action)
        l_q = q_loss(q1, q2, target)
        metrics = {
            "value_loss": l_v.item(),
            "q_loss": l_q.item(),
            "v_mean": v.mean().item(),
            "q_mean": torch.minimum(q1, q2).mean().item(),
            "td_abs": (torch.minimum(q1, q2) - target).abs().mean().item(),
        }
        return l_v + l_q, metrics

    def update_target(self, rate: float) -> None:
        """Polyak step of the target Qs toward the online Qs."""
        polyak_update(self.q_target, self.q, rate)


def iql_step(
    critic: IqlCritic,
    batch: IqlBatch,
    optimizer: torch.optim.Optimizer,
    tau: float,
    polyak: float,
    grad_clip_norm: float | None = None,
) -> dict[str, float]:
    """One optimiser step on both losses, then the Polyak update; returns the logged scalars."""
    loss, metrics = critic.losses(batch, tau)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if grad_clip_norm is not None:
        params = [p for g in optimizer.param_groups for p in g["params"]]
        metrics["grad_norm"] = float(torch.nn.utils.clip_grad_norm_(params, grad_clip_norm))
    optimizer.step()
    critic.update_target(polyak)
    return metrics
