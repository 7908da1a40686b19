"""The ``ur5`` LeRobot robot: a UR5/UR5e with a parallel gripper and a wrist GoPro.

Features are the datasets' quantities under names LeRobot's CLIs keep: ``lerobot-rollout`` passes a
policy only cameras and scalars ending in ``.pos``/``.vel``, and both ``lerobot-record`` and
``lerobot-rollout`` pack every scalar into one ``observation.state``. So the observation is

* ``wrist``: the 224x224 RGB wrist image (-> ``observation.images.wrist``),
* ``tcp_x.pos ... tcp_r12.pos, gripper_width.pos``: the absolute TCP pose10 (table frame),
* ``bbox_x0.pos ... bbox_y1.pos``: the target box (normalised; zeros when lost),

which LeRobot stores as a 14-float ``observation.state`` (pose10, then the box). ``bbox_diffusion``'s
preprocessor splits such a state into ``observation.state`` (10) and ``observation.bbox`` (4), so the
same checkpoint runs under ``lerobot-eval`` (separate keys) and ``lerobot-rollout`` (packed). The action is
the absolute pose10 target ``tcp_*.pos, gripper_width.pos``.
"""

from __future__ import annotations

import logging
from functools import cached_property
from typing import Any

import numpy as np
from lerobot.robots.robot import Robot

from lerobot_bboxpick import geometry
from lerobot_bboxpick.data.features import POSE10_NAMES
from lerobot_bboxpick.robots.ur5 import sim_link
from lerobot_bboxpick.robots.ur5.backend import ArmBackend
from lerobot_bboxpick.robots.ur5.configuration_ur5 import UR5Config, parse_bbox
from lerobot_bboxpick.robots.ur5.safety import UnsafeActionError, pose10_to_target
from lerobot_bboxpick.robots.ur5.target_prompt import TargetPrompt
from lerobot_bboxpick.robots.ur5.wrist_image import IMAGE_SIZE, umi_wrist_crop

log = logging.getLogger(__name__)

CAMERA = "wrist"
POSE_KEYS = tuple(f"tcp_{n}.pos" for n in POSE10_NAMES[:9]) + ("gripper_width.pos",)
BBOX_KEYS = tuple(f"bbox_{n}.pos" for n in ("x0", "y0", "x1", "y1"))


class UR5(Robot):
    """UR5/UR5e + gripper + wrist GoPro, on the MuJoCo twin or a real arm (``config.backend``)."""

    config_class = UR5Config
    name = "ur5"

    def __init__(self, config: UR5Config) -> None:
        super().__init__(config)
        self.config = config
        self.backend: ArmBackend | None = None
        self.cameras: dict = {}
        self.prompt = TargetPrompt(config.bbox_source, config.max_lost_frames)
        self._T_sent: np.ndarray | None = None  # last commanded TCP target (speed limits start from it)
        self._v_sent: np.ndarray | None = None  # its linear velocity (m/s), for the acceleration bound
        self._halted = False  # the target is gone: the arm holds still and actions are ignored
        self._link_id = config.id or "default"

    # ------------------------------------------------------------------ features
    @cached_property
    def observation_features(self) -> dict[str, type | tuple]:
        """The wrist image and 14 scalars: pose10 then the target box."""
        return {CAMERA: (IMAGE_SIZE, IMAGE_SIZE, 3), **dict.fromkeys(POSE_KEYS + BBOX_KEYS, float)}

    @cached_property
    def action_features(self) -> dict[str, type]:
        """The absolute pose10 target."""
        return dict.fromkeys(POSE_KEYS, float)

    # ------------------------------------------------------------------ lifecycle
    @property
    def is_connected(self) -> bool:
        """Whether the arm (and camera) are connected."""
        return self.backend is not None and self.backend.is_connected

    @property
    def is_calibrated(self) -> bool:
        """Nothing to calibrate (the table frame is a setting: ``base_from_table``)."""
        return True

    def calibrate(self) -> None:
        """No-op: the arm's kinematics are factory calibrated; the table frame is ``base_from_table``."""

    def configure(self) -> None:
        """No-op: the backends configure themselves at connect."""

    def connect(self, calibrate: bool = True) -> None:
        """Connect the arm, gripper and camera, then take the target on the first frame."""
        if self.is_connected:
            raise RuntimeError(f"{self} is already connected")
        self.backend = self._make_backend()
        self.backend.connect()
        if self.config.backend == "mujoco":
            sim_link.publish(self._link_id, self.backend)
        else:
            from lerobot.cameras.utils import make_cameras_from_configs

            self.cameras = make_cameras_from_configs(self.config.cameras)
            for camera in self.cameras.values():
                camera.connect()
        self._start_target()
        log.info("%s connected (backend %s, bbox %s)", self, self.config.backend, self.config.bbox_source)

    def disconnect(self) -> None:
        """Stop the arm and close everything (also on Ctrl-C: LeRobot's CLIs disconnect in ``finally``)."""
        if self.backend is not None:
            sim_link.withdraw(self._link_id)
            self.backend.disconnect()
        for camera in self.cameras.values():
            if camera.is_connected:
                camera.disconnect()

    # ------------------------------------------------------------------ observation / action
    def get_observation(self) -> dict[str, Any]:
        """The wrist image, the measured pose10 and the target box."""
        backend = self._live()
        if self.config.backend == "mujoco" and backend.poll_scene():
            self._start_target()  # a new scene: a new target
        frame = self._frame()
        oracle = backend.oracle_bbox() if self.config.backend == "mujoco" else None
        box = self.prompt.update(frame, oracle)
        if self.prompt.gone and not self._halted:
            self._halted = True
            backend.stop()
            log.error(
                "target lost for %d frames: the arm is stopped and ignores actions until a new target is "
                "given (a new scene in the simulator; on a real arm: reconnect with a new box)",
                self.prompt.lost_frames,
            )
        pose10 = np.concatenate([geometry.mat_to_pose9(backend.tcp_pose()), [backend.gripper_width()]])
        obs: dict[str, Any] = {CAMERA: frame}
        obs.update({k: float(v) for k, v in zip(POSE_KEYS, pose10, strict=True)})
        obs.update({k: float(v) for k, v in zip(BBOX_KEYS, box, strict=True)})
        return obs

    def send_action(self, action: dict[str, Any]) -> dict[str, float]:
        """Check ``action`` (absolute pose10), limit its speed, send it; returns what was sent.

        Raises ``UnsafeActionError`` naming the field for a missing, unknown, non-finite or out-of-box
        value: nothing moves then. The box keys (``bbox_*.pos``) are observations and are ignored here,
        since LeRobot's return-to-start sends every ``.pos`` key it observed.
        """
        backend = self._live()
        missing = [k for k in POSE_KEYS if k not in action]
        unknown = [k for k in action if k not in POSE_KEYS and k not in BBOX_KEYS]
        if missing or unknown:
            raise UnsafeActionError(
                f"action keys missing {missing} / unknown {unknown}; the ur5 action is {list(POSE_KEYS)}"
            )
        a = self.config.safety.check_pose10([float(action[k]) for k in POSE_KEYS])
        if self._halted:
            return self._as_action(self._T_sent if self._T_sent is not None else backend.tcp_pose(), a[9])
        T, width = pose10_to_target(a)
        dt = 1.0 / self.config.fps
        T_from = self._T_sent if self._T_sent is not None else backend.tcp_pose()
        T, _ = self.config.safety.limit_velocity(T_from, T, dt, self._v_sent)
        backend.command(T, width)
        self._v_sent = (T[:3, 3] - T_from[:3, 3]) / dt
        self._T_sent = T
        return self._as_action(T, width)

    # ------------------------------------------------------------------ internals
    def _make_backend(self) -> ArmBackend:
        c = self.config
        if c.backend == "mujoco":
            from lerobot_bboxpick.robots.ur5.mujoco_backend import MujocoArm

            return MujocoArm(
                c.setting,
                c.seed,
                c.scene_time_s,
                domain_randomization=c.domain_randomization,
                max_tcp_speed=c.safety.max_tcp_speed,
                max_tcp_angular_speed=c.safety.max_tcp_angular_speed,
            )
        from lerobot_bboxpick.robots.ur5.rtde_backend import make_rtde_arm

        return make_rtde_arm(c)

    def _frame(self) -> np.ndarray:
        if self.config.backend == "mujoco":
            return self._live().camera_frame()
        camera = next(iter(self.cameras.values()))
        return umi_wrist_crop(camera.async_read())

    def _start_target(self) -> None:
        """Take the target on the current first frame: --robot.bbox, the web picker, or the scene's own."""
        backend = self._live()
        self._halted = False
        self._T_sent = self._v_sent = None
        box = None
        # The tracker starts on the very frame the box was drawn on: on a real arm a later frame may
        # already show the scene moved.
        frame = self._frame()
        if self.config.bbox is not None:
            box = np.array(parse_bbox(self.config.bbox), dtype=np.float32)
        elif self.config.bbox_picker == "web":
            from lerobot_bboxpick.apps.dashboard.box_picker import pick_box_in_browser

            box = pick_box_in_browser(frame, port=self.config.bbox_picker_port)
        if self.config.backend == "mujoco":
            if box is not None:
                brick = backend.designate(box)
                log.info("target: brick %d (the one under the box)", brick)
                frame = self._frame()  # the scene was reloaded with that target (same seed, same image)
            else:
                box = backend.oracle_bbox()
        assert box is not None
        self.prompt.start(frame, box)

    @staticmethod
    def _as_action(T: np.ndarray, width: float) -> dict[str, float]:
        pose10 = np.concatenate([geometry.mat_to_pose9(T), [width]])
        return {k: float(v) for k, v in zip(POSE_KEYS, pose10, strict=True)}

    def _live(self) -> Any:
        if self.backend is None or not self.backend.is_connected:
            raise RuntimeError(f"{self} is not connected: call connect() first")
        return self.backend
