"""One closed-loop episode of a LeRobot policy checkpoint in ``LegoPickEnv``.

Observations go through LeRobot's own ``preprocess_observation`` (as in ``lerobot-eval``), then the
checkpoint's saved preprocessor, the policy, and its saved postprocessor; so what runs here is what
``lerobot-eval`` runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch


@dataclass
class PolicyRunner:
    """A policy with its pre/post-processors, loaded from a ``save_pretrained`` folder."""

    policy: Any
    preprocessor: Any
    postprocessor: Any

    @classmethod
    def from_pretrained(
        cls, path: str | Path, device: str = "cpu", n_action_steps: int | None = None
    ) -> PolicyRunner:
        """Load like ``lerobot-eval --policy.path=path``; ``n_action_steps`` overrides the steps executed
        per predicted chunk (like ``--policy.n_action_steps``)."""
        from lerobot.configs import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        config = PreTrainedConfig.from_pretrained(path)
        config.device = device
        if n_action_steps is not None:
            config.n_action_steps = n_action_steps
        policy = get_policy_class(config.type).from_pretrained(path, config=config)
        policy.eval()
        pre, post = make_pre_post_processors(
            config,
            pretrained_path=str(path),
            preprocessor_overrides={"device_processor": {"device": device}},
        )
        return cls(policy, pre, post)

    def reset(self) -> None:
        """Start of an episode."""
        self.policy.reset()
        self.preprocessor.reset()
        self.postprocessor.reset()

    def observation_batch(self, observation: dict, task: str) -> dict:
        """One env observation through LeRobot's ``preprocess_observation`` and the saved preprocessor."""
        from lerobot.envs.utils import preprocess_observation

        batch = preprocess_observation({k: _batched(v) for k, v in observation.items()})
        batch["task"] = [task]
        return self.preprocessor(batch)

    @torch.no_grad()
    def act(self, observation: dict, task: str) -> np.ndarray:
        """Absolute 10-float action for one env observation."""
        action = self.postprocessor(self.policy.select_action(self.observation_batch(observation, task)))
        return action[0].cpu().numpy().astype(np.float64)


class ExpertRunner:
    """The scripted expert behind ``PolicyRunner``'s interface: the suite's upper-bound row.

    Its variation (speed, approach offset) is seeded by the episode seed, so it is deterministic per scene.
    """

    def __init__(self, env: Any) -> None:
        self.env = env
        self.expert: Any = None

    def reset(self) -> None:
        """Plan a pick of the target from the env's just-reset state."""
        from lerobot_bboxpick.expert import ScriptedExpert

        self.expert = ScriptedExpert(np.random.default_rng(self.env.episode_seed))
        self.expert.reset(self.env)

    def act(self, observation: dict, task: str) -> np.ndarray:
        """The next planned action (the observation is not needed: the expert has privileged state)."""
        return self.expert.act()


def _batched(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _batched(v) for k, v in value.items()}
    return np.asarray(value)[None]


def rollout(
    runner: PolicyRunner,
    setting: str,
    seed: int,
    policy_seed: int = 0,
    max_steps: int = 300,
    video_path: Path | None = None,
    env: Any | None = None,
    options: dict | None = None,
) -> dict:
    """Run one episode; returns outcome, steps and the final gripper-to-target distance."""
    from lerobot_bboxpick.sim.env import LegoPickEnv
    from lerobot_bboxpick.viz import save_mp4

    own_env = env is None
    env = env or LegoPickEnv(setting=setting, episode_length=max_steps)
    torch.manual_seed(policy_seed)
    obs, info = env.reset(seed=seed, options=options)
    runner.reset()
    frames = [env.render()] if video_path else []
    steps = 0
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(runner.act(obs, info["task"]))
        steps += 1
        done = terminated or truncated
        if video_path:
            frames.append(env.render())
    distance = float(np.linalg.norm(env.tcp_pose()[:3, 3] - env.brick_pose(env.target)[:3, 3]))
    if video_path:
        save_mp4(video_path, frames, env.options.fps)
    result = {
        "setting": setting,
        "seed": seed,
        "policy_seed": policy_seed,
        "target": env.target,
        "outcome": info["outcome"],
        "steps": steps,
        "final_distance_m": distance,
        "sim_unstable": bool(info.get("sim_unstable", False)),
    }
    if own_env:
        env.close()
    return result
