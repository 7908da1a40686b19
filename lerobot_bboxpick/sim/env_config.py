"""LeRobot registration of the ``lego_pick`` env: ``lerobot-eval --env.type=lego_pick --env.setting=...``.

LeRobot maps the env's ``pixels["wrist"]`` to ``observation.images.wrist``, ``agent_pos`` to
``observation.state`` and ``bbox`` to ``observation.bbox`` (``preprocess_observation``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.envs.utils import freeze_after_episode_end

from lerobot_bboxpick.keys import (
    ACTION,
    BBOX,
    ENV_BBOX,
    ENV_CAMERA,
    ENV_PIXELS,
    ENV_STATE,
    STATE,
    WRIST_IMAGE,
)
from lerobot_bboxpick.sim.layouts import SETTINGS, check_setting

_PIXELS = f"{ENV_PIXELS}/{ENV_CAMERA}"


@EnvConfig.register_subclass("lego_pick")
@dataclass
class LegoPickEnvConfig(EnvConfig):
    """The lego_pick MuJoCo env: UR5e + UMI gripper, twelve DUPLO bricks, one bbox-designated target."""

    task: str | None = "lego_pick"
    fps: int = 20
    episode_length: int = 300
    # One of SETTINGS: grid_id, grid_ood, pile_id, random_id, identical_2, identical_4.
    setting: str = "grid_id"
    # Wrist lens: "gopro_hero10" (UMI's GoPro calibration) or "equidistant".
    lens: str = "gopro_hero10"
    domain_randomization: bool = True
    # End the episode once a brick has been lifted (its outcome is then decided).
    terminate_on_lift: bool = True
    # Commanded TCP speed limits (m/s, rad/s), as a real arm's driver enforces them.
    max_tcp_speed: float = 0.5
    max_tcp_angular_speed: float = 1.5
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(10,)),
            ENV_STATE: PolicyFeature(type=FeatureType.STATE, shape=(10,)),
            _PIXELS: PolicyFeature(type=FeatureType.VISUAL, shape=(224, 224, 3)),
            ENV_BBOX: PolicyFeature(type=FeatureType.STATE, shape=(4,)),
        }
    )
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION: ACTION,
            ENV_STATE: STATE,
            _PIXELS: WRIST_IMAGE,
            ENV_BBOX: BBOX,
        }
    )

    def __post_init__(self) -> None:
        check_setting(self.setting)
        if self.episode_length < 1:
            raise ValueError(f"episode_length={self.episode_length} must be >= 1")

    @property
    def gym_kwargs(self) -> dict:
        """Options passed to ``LegoPickEnv``."""
        return {
            "setting": self.setting,
            "episode_length": self.episode_length,
            "fps": self.fps,
            "lens": self.lens,
            "domain_randomization": self.domain_randomization,
            "terminate_on_lift": self.terminate_on_lift,
            "max_tcp_speed": self.max_tcp_speed,
            "max_tcp_angular_speed": self.max_tcp_angular_speed,
        }

    def create_envs(
        self, n_envs: int, use_async_envs: bool = False
    ) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        """``{"lego_pick": {0: VectorEnv}}`` of ``n_envs`` envs of this setting."""
        from lerobot_bboxpick.sim.env import LegoPickEnv  # deferred: rendering set-up only when used

        kwargs = self.gym_kwargs
        factory = freeze_after_episode_end(lambda: LegoPickEnv(**kwargs))
        # SAME_STEP autoreset, as LeRobot's own envs: the rollout reads the final step's info.
        mode = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}
        if use_async_envs and n_envs > 1:
            vec = gym.vector.AsyncVectorEnv([factory] * n_envs, context="forkserver", **mode)
        else:
            vec = gym.vector.SyncVectorEnv([factory] * n_envs, **mode)
        return {self.type: {0: vec}}


__all__ = ["LegoPickEnvConfig", "SETTINGS"]
