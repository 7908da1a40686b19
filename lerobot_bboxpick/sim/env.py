"""``LegoPickEnv``: the gymnasium env of the lego_pick task.

Observation: ``pixels["wrist"]`` (224x224x3 uint8 fisheye), ``agent_pos`` (10: TCP position, rot6d,
gripper width; table frame) and ``bbox`` (4: x0, y0, x1, y1 of the target, normalised).
Action: 10 floats, the absolute target TCP pose (position, rot6d) and gripper width, at 20 Hz.
Each step runs mink IK once and drives the joint position actuators over the physics substeps.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from lerobot_bboxpick import geometry
from lerobot_bboxpick.keys import ENV_BBOX, ENV_CAMERA, ENV_PIXELS, ENV_STATE
from lerobot_bboxpick.sim.camera import LENSES, BoxProjection, WristCamera
from lerobot_bboxpick.sim.controller import (
    WORKSPACE_HIGH,
    WORKSPACE_LOW,
    IkResult,
    TcpIkController,
    limit_step,
)
from lerobot_bboxpick.sim.layouts import Layout, check_setting, describe_target, make_layout, scene_rng
from lerobot_bboxpick.sim.outcome import OutcomeTracker
from lerobot_bboxpick.sim.randomization import Randomizer
from lerobot_bboxpick.sim.scene import (
    MAX_GRIPPER_WIDTH,
    N_BRICKS,
    WRIST_CAMERA,
    SceneIds,
    brick_silhouette_points,
    build_model,
)
from lerobot_bboxpick.viz import draw_bbox

ACTION_DIM = 10
IMAGE_SIZE = 224
# Start pose: TCP 22 cm above the table, the approach axis pitched 35 deg forward so the wrist
# camera sees the whole workspace; gripper open. Columns of the top-down rotation: finger axis
# = -y (image right is the robot's right), camera-down axis = -x, approach axis = -z.
_TOP_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T
START_POSITION = np.array([0.42, 0.0, 0.22])
START_PITCH_DEG = 35.0
START_GRIPPER_WIDTH = 0.08
# Arm posture the start-pose IK begins from (elbow up, wrist down).
_IK_SEED = np.array([-np.pi, -1.9, 1.9, -1.57, -1.5708, 0.0])
SETTLE_SECONDS = 0.3
RAMP_STAGES = 5  # joint-target ramp stages per control period


def start_rotation(pitch_deg: float = START_PITCH_DEG) -> np.ndarray:
    """Rotation of the TCP at the start pose (table frame)."""
    return Rotation.from_euler("y", -pitch_deg, degrees=True).as_matrix() @ _TOP_DOWN


def start_pose10(width: float = START_GRIPPER_WIDTH) -> np.ndarray:
    """The nominal start pose as a 10-float absolute action."""
    T = np.eye(4)
    T[:3, :3] = start_rotation()
    T[:3, 3] = START_POSITION
    return np.concatenate([geometry.mat_to_pose9(T), [width]])


@cache
def _start_joint_angles() -> tuple[float, ...]:
    """IK of the nominal start pose, solved once per process from a fixed seed."""
    controller = TcpIkController(_IK_SEED)
    T = geometry.pose9_to_mat(start_pose10()[:9])
    q = _IK_SEED
    for _ in range(10):
        result = controller.solve(q, T)
        q = result.q_arm
        if not result.unreachable:
            break
    return tuple(float(v) for v in q)


@dataclass(frozen=True)
class LegoPickOptions:
    """Construction options of ``LegoPickEnv`` (the LeRobot config maps onto these)."""

    setting: str = "grid_id"
    episode_length: int = 300
    fps: int = 20
    lens: str = "gopro_hero10"
    render_size: int = 512
    render_fovy_deg: float = 140.0
    domain_randomization: bool = True
    terminate_on_lift: bool = True
    start_jitter: bool = True
    # Commanded TCP speed limits, as a real arm's driver enforces them (UMI's limits its waypoints
    # too). The expert moves at most 0.36 m/s and 0.9 rad/s; without a limit a far target makes the
    # joint-space swing dive the fingers into the table, where friction then holds them.
    max_tcp_speed: float = 0.5  # m/s
    max_tcp_angular_speed: float = 1.5  # rad/s


class LegoPickEnv(gym.Env):
    """UR5e + UMI gripper picking the bbox-designated one of twelve DUPLO bricks."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, render_mode: str | None = "rgb_array", **options: Any) -> None:
        unknown = set(options) - set(LegoPickOptions.__dataclass_fields__)
        if unknown:
            raise TypeError(
                f"unknown LegoPickEnv option(s) {sorted(unknown)}; "
                f"valid: {sorted(LegoPickOptions.__dataclass_fields__)}"
            )
        self.options = LegoPickOptions(**options)
        check_setting(self.options.setting)
        if self.options.lens not in LENSES:
            raise ValueError(f"lens={self.options.lens!r} is not known; valid lenses: {', '.join(LENSES)}")
        for name in ("max_tcp_speed", "max_tcp_angular_speed"):
            if not getattr(self.options, name) > 0:
                raise ValueError(f"{name}={getattr(self.options, name)!r} must be > 0")
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.options.fps}
        self.model = build_model()
        self.data = mujoco.MjData(self.model)
        self.ids = SceneIds.of(self.model)
        self.camera = WristCamera(
            self.model,
            WRIST_CAMERA,
            self.ids.camera_site,
            LENSES[self.options.lens](),
            render_size=self.options.render_size,
            fovy_deg=self.options.render_fovy_deg,
        )
        self.controller = TcpIkController(np.array(_start_joint_angles()))
        self.randomizer = Randomizer(self.model, self.ids, enabled=self.options.domain_randomization)
        self.n_substeps = max(1, round(1.0 / (self.options.fps * self.model.opt.timestep)))
        stages = min(RAMP_STAGES, self.n_substeps)
        self._ramp = [len(c) for c in np.array_split(np.arange(self.n_substeps), stages)]
        self._silhouette = brick_silhouette_points()
        self._max_episode_steps = self.options.episode_length

        self.observation_space = gym.spaces.Dict(
            {
                ENV_PIXELS: gym.spaces.Dict(
                    {ENV_CAMERA: gym.spaces.Box(0, 255, (IMAGE_SIZE, IMAGE_SIZE, 3), dtype=np.uint8)}
                ),
                ENV_STATE: gym.spaces.Box(-np.inf, np.inf, (ACTION_DIM,), dtype=np.float32),
                ENV_BBOX: gym.spaces.Box(0.0, 1.0, (4,), dtype=np.float32),
            }
        )
        low = np.concatenate([WORKSPACE_LOW, -np.ones(6), [0.0]]).astype(np.float32)
        high = np.concatenate([WORKSPACE_HIGH, np.ones(6), [MAX_GRIPPER_WIDTH]]).astype(np.float32)
        self.action_space = gym.spaces.Box(low, high, dtype=np.float32)

        self.layout: Layout | None = None
        self.task_description = "pick up the block in the box"
        self.task = self.task_description
        self.episode_seed: int | None = None
        self._tracker: OutcomeTracker | None = None
        self._q_cmd = np.array(_start_joint_angles())
        self._T_cmd = self.controller.forward(self._q_cmd)
        self._width_cmd = START_GRIPPER_WIDTH
        self._last_image: np.ndarray | None = None
        self._last_box: BoxProjection | None = None
        self._steps = 0

    # ------------------------------------------------------------------ state readers
    def tcp_pose(self) -> np.ndarray:
        """Current TCP pose (4x4, table frame)."""
        T = np.eye(4)
        T[:3, :3] = self.data.site_xmat[self.ids.tcp_site].reshape(3, 3)
        T[:3, 3] = self.data.site_xpos[self.ids.tcp_site]
        return T

    def gripper_width(self) -> float:
        """Current distance between the finger pads (m)."""
        return float(self.data.qpos[self.ids.finger_qpos].sum())

    def agent_pos(self) -> np.ndarray:
        """TCP pose + gripper width as 10 floats (the same representation as the action)."""
        return np.concatenate([geometry.mat_to_pose9(self.tcp_pose()), [self.gripper_width()]]).astype(
            np.float32
        )

    def brick_pose(self, index: int) -> np.ndarray:
        """Pose (4x4) of a brick's bottom-face centre frame."""
        T = np.eye(4)
        T[:3, :3] = self.data.xmat[self.ids.brick_bodies[index]].reshape(3, 3)
        T[:3, 3] = self.data.xpos[self.ids.brick_bodies[index]]
        return T

    def brick_box(self, index: int) -> BoxProjection:
        """The projected bbox of a brick in the current wrist view."""
        T = self.brick_pose(index)
        return self.camera.project_bbox(self.data, self._silhouette @ T[:3, :3].T + T[:3, 3])

    def render_brick_masks(self) -> np.ndarray:
        """(H, W) int brick index of each wrist pixel, -1 elsewhere (real segmentation render)."""
        geoms = self.camera.render_geom_ids(self.data)
        out = np.full(geoms.shape, -1, dtype=np.int32)
        valid = geoms >= 0
        out[valid] = self.ids.brick_of_geom[geoms[valid]]
        return out

    @property
    def target(self) -> int:
        """Index of the target brick."""
        if self.layout is None:
            raise RuntimeError("call reset() before reading the target")
        return self.layout.target

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """New scene from ``seed``.

        ``options`` may hold ``layout`` (a Layout to use instead of the seed's), ``target`` (a brick
        index to designate instead) and ``start_pose`` (a 4x4 TCP pose to start from instead of the
        seed's jittered start pose; e.g. to replay a mirrored episode).
        """
        super().reset(seed=seed)
        options = options or {}
        if seed is None:
            seed = int(self.np_random.integers(0, 2**31 - 1))
        self.episode_seed = seed
        rng = scene_rng(self.options.setting, seed)
        layout = options.get("layout") or make_layout(self.options.setting, rng)
        if "target" in options:
            target = int(options["target"])
            if not 0 <= target < N_BRICKS:
                raise ValueError(f"options['target']={target} must be a brick index in [0, {N_BRICKS - 1}]")
            layout = Layout(layout.setting, layout.positions, layout.yaws, layout.colors, target)
        self.layout = layout
        self.randomizer.apply(self.randomizer.sample(layout.colors, rng))

        mujoco.mj_resetData(self.model, self.data)
        for i in range(N_BRICKS):
            adr = self.ids.brick_qpos[i]
            self.data.qpos[adr : adr + 3] = layout.positions[i]
            self.data.qpos[adr + 3 : adr + 7] = [np.cos(layout.yaws[i] / 2), 0, 0, np.sin(layout.yaws[i] / 2)]
        q_start = np.array(_start_joint_angles())
        T_start = geometry.pose9_to_mat(start_pose10()[:9])
        if self.options.start_jitter:
            # Small seeded variation of the start pose so demonstrations do not all begin alike.
            T_start[:3, 3] += rng.uniform(-0.015, 0.015, size=3)
            T_start[:3, :3] = (
                Rotation.from_rotvec(rng.uniform(-0.05, 0.05, size=3)).as_matrix() @ T_start[:3, :3]
            )
        if "start_pose" in options:
            T_start = np.asarray(options["start_pose"], dtype=np.float64)
            if T_start.shape != (4, 4):
                raise ValueError(f"options['start_pose'] must be a 4x4 pose, got shape {T_start.shape}")
        for _ in range(3):  # a start pose far from the nominal one may need a few IK rounds
            result = self.controller.solve(q_start, T_start)
            q_start = result.q_arm
            if not result.unreachable:
                break
        self.data.qpos[self.ids.arm_qpos] = q_start
        self.data.qpos[self.ids.finger_qpos] = START_GRIPPER_WIDTH / 2
        self._q_cmd = q_start.copy()
        self._T_cmd = self.controller.forward(q_start)
        self._width_cmd = START_GRIPPER_WIDTH
        self._write_ctrl(self._q_cmd, self._width_cmd)
        mujoco.mj_forward(self.model, self.data)
        # Let the bricks settle (a pile's stacked bricks find their rest) before the first frame.
        mujoco.mj_step(self.model, self.data, nstep=round(SETTLE_SECONDS / self.model.opt.timestep))
        mujoco.mj_forward(self.model, self.data)

        # Resting heights after the settle: a stacked brick is lifted from where it lies, not from the table.
        self._tracker = OutcomeTracker(self.ids, layout.target, self.data.xpos[self.ids.brick_bodies, 2])
        self._steps = 0
        self.task_description = describe_target(layout)
        self.task = self.task_description
        obs = self._observe()
        return obs, self._info(ik=None)

    def step(self, action: np.ndarray):
        """Move toward the absolute TCP pose + gripper width in ``action`` for one control period."""
        if self._tracker is None:
            raise RuntimeError("call reset() before step()")
        action = self._check_action(action)
        T, speed_limited = limit_step(
            self._T_cmd,
            geometry.pose9_to_mat(action[:9]),
            self.options.max_tcp_speed / self.options.fps,
            self.options.max_tcp_angular_speed / self.options.fps,
        )
        width = float(action[9])
        width_clamped = not 0.0 <= width <= MAX_GRIPPER_WIDTH
        width = float(np.clip(width, 0.0, MAX_GRIPPER_WIDTH))
        ik = self.controller.solve(self._q_cmd, T)
        q_from, w_from = self._q_cmd, self._width_cmd
        for k, nstep in enumerate(self._ramp, start=1):
            # Ramp the joint targets over the control period in a few stages: smooth torques,
            # no step jumps; outcome contacts are read after every stage (every 10 ms).
            a = k / len(self._ramp)
            self._write_ctrl(q_from + a * (ik.q_arm - q_from), w_from + a * (width - w_from))
            mujoco.mj_step(self.model, self.data, nstep=nstep)
            self._tracker.update(self.data)
        self._tracker.end_step(self.data)
        self._q_cmd, self._width_cmd, self._T_cmd = ik.q_arm, width, T
        self._steps += 1
        obs = self._observe()
        info = self._info(ik=ik, width_clamped=width_clamped, speed_limited=speed_limited)
        outcome = info["outcome"]
        reward = 1.0 if outcome == "pick" else 0.0
        # A blown-up simulation ends the episode: what follows it is not physics (its outcome stays
        # what was tracked before, and info["sim_unstable"] says so).
        terminated = (self.options.terminate_on_lift and outcome in ("pick", "wrong")) or info["sim_unstable"]
        truncated = self._steps >= self.options.episode_length
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The last wrist frame with the target bbox drawn (for videos)."""
        if self._last_image is None:
            return None
        frame = self._last_image.copy()
        if self._last_box is not None and self._last_box.in_view:
            draw_bbox(frame, self._last_box.bbox)
        return frame

    def close(self) -> None:
        """Free the renderers."""
        self.camera.close()

    # ------------------------------------------------------------------ internals
    def _check_action(self, action: Any) -> np.ndarray:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (ACTION_DIM,):
            raise ValueError(
                f"action must have shape ({ACTION_DIM},) = position(3) + rot6d(6) + gripper width(1), "
                f"got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            bad = [i for i in range(ACTION_DIM) if not np.isfinite(a[i])]
            raise ValueError(f"action has non-finite values at indices {bad}: {a.tolist()}")
        if np.linalg.norm(a[3:6]) < 1e-6 or np.linalg.norm(a[6:9]) < 1e-6:
            raise ValueError("action rot6d rows (indices 3:6 and 6:9) must be non-zero vectors")
        return a

    def _write_ctrl(self, q_arm: np.ndarray, width: float) -> None:
        self.data.ctrl[self.ids.arm_actuators] = q_arm
        self.data.ctrl[self.ids.finger_actuators] = width / 2

    def _observe(self) -> dict[str, Any]:
        image = self.camera.render(self.data)
        box = self.brick_box(self.target)
        self._last_image, self._last_box = image, box
        return {ENV_PIXELS: {ENV_CAMERA: image}, ENV_STATE: self.agent_pos(), ENV_BBOX: box.bbox.copy()}

    def _info(
        self, ik: IkResult | None, width_clamped: bool = False, speed_limited: bool = False
    ) -> dict[str, Any]:
        assert self._tracker is not None and self._last_box is not None and self.layout is not None
        outcome = self._tracker.outcome
        return {
            "outcome": outcome,
            "is_success": outcome == "pick",
            "bbox_visibility": self._last_box.visibility,
            "target_in_view": self._last_box.in_view,
            "target": self.layout.target,
            "setting": self.layout.setting,
            "seed": self.episode_seed,
            "task": self.task_description,
            "ik_clamped": bool(ik.clamped) if ik else False,
            "ik_position_error": float(ik.position_error) if ik else 0.0,
            "gripper_width_clamped": width_clamped,
            "speed_limited": speed_limited,
            "sim_unstable": self._tracker.unstable,
        }
