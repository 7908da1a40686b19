"""One closed-loop episode of a LeRobot policy checkpoint in ``LegoPickEnv``.

Observations go through LeRobot's own ``preprocess_observation`` (as in ``lerobot-eval``), then the
checkpoint's saved preprocessor, the policy, and its saved postprocessor; so what runs here is what
``lerobot-eval`` runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lerobot_bboxpick.eval.bbox_source import BboxSource
from lerobot_bboxpick.keys import ENV_BBOX


@dataclass
class PolicyRunner:
    """A policy with its pre/post-processors, loaded from a ``save_pretrained`` folder."""

    policy: Any
    preprocessor: Any
    postprocessor: Any

    @classmethod
    def from_pretrained(
        cls,
        path: str | Path,
        device: str = "cpu",
        n_action_steps: int | None = None,
        num_inference_steps: int | None = None,
        onnx_inference: bool = False,
    ) -> PolicyRunner:
        """Load like ``lerobot-eval --policy.path=path``; ``n_action_steps`` overrides the steps executed
        per predicted chunk (like ``--policy.n_action_steps``), ``num_inference_steps`` the denoising
        steps per chunk (a diffusion policy's ``--policy.num_inference_steps``); ``onnx_inference`` runs a
        ``bbox_diffusion`` encoder and sampling loop in ONNX Runtime (``--policy.onnx_inference=true``)."""
        from lerobot.configs import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        config = PreTrainedConfig.from_pretrained(path)
        config.device = device
        if n_action_steps is not None:
            config.n_action_steps = n_action_steps
        if num_inference_steps is not None:
            if not hasattr(config, "num_inference_steps"):
                raise ValueError(f"num_inference_steps: policy type {config.type!r} has no denoising steps")
            config.num_inference_steps = num_inference_steps
        if onnx_inference:
            if not hasattr(config, "onnx_inference"):
                raise ValueError(f"onnx_inference: policy type {config.type!r} has no ONNX Runtime path")
            config.onnx_inference = True
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
        from lerobot_bboxpick.sim.expert import ScriptedExpert

        self.expert = ScriptedExpert(np.random.default_rng(self.env.episode_seed))
        self.expert.reset(self.env)

    def act(self, observation: dict, task: str) -> np.ndarray:
        """The next planned action (the observation is not needed: the expert has privileged state)."""
        return self.expert.act()


# Called after every env step with (observation before the step, its info, the action executed, the step's
# reward, the info after the step): what a recorder needs to write frame t.
StepHook = Callable[[dict, dict, np.ndarray, float, dict], None]


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
    bbox_source: BboxSource | None = None,
    on_step: StepHook | None = None,
) -> dict:
    """Run one episode; returns outcome, steps and the final gripper-to-target distance.

    ``bbox_source`` decides the bbox the policy sees (default: the oracle box); videos draw the
    oracle box in white and, when they differ, the given box in yellow. ``on_step`` sees every step
    (``bboxpick-rollouts`` records the episode through it).
    """
    from lerobot_bboxpick.sim.env import LegoPickEnv
    from lerobot_bboxpick.viz import draw_bbox, save_mp4

    own_env = env is None
    env = env or LegoPickEnv(setting=setting, episode_length=max_steps)
    source = bbox_source or BboxSource("oracle")
    torch.manual_seed(policy_seed)
    obs, info = env.reset(seed=seed, options=options)
    obs = source.reset(obs, seed)
    runner.reset()

    def frame() -> np.ndarray:
        image = env.render()
        if source.name != "oracle" and obs[ENV_BBOX][2] > obs[ENV_BBOX][0]:
            draw_bbox(image, obs[ENV_BBOX], color=(255, 220, 0))
        return image

    frames = [frame()] if video_path else []
    steps = 0
    done = False
    while not done:
        action = runner.act(obs, info["task"])
        next_obs, reward, terminated, truncated, next_info = env.step(action)
        if on_step is not None:
            on_step(obs, info, action, float(reward), next_info)
        obs, info = source(next_obs), next_info
        steps += 1
        done = terminated or truncated
        if video_path:
            frames.append(frame())
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
        "bbox_source": source.name,
        "bbox_mean_iou": None if source.mean_iou is None else round(source.mean_iou, 4),
        "bbox_lost_frames": source.lost_frames,
    }
    if own_env:
        env.close()
    return result
