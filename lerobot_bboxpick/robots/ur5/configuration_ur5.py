"""``--robot.type=ur5``: the UR5/UR5e + parallel gripper + wrist GoPro of the paper, as a LeRobot robot.

    lerobot-record --robot.type=ur5 --robot.backend=mujoco --teleop.type=bboxpick_expert ...
    lerobot-rollout --robot.type=ur5 --robot.backend=rtde --robot.host=<arm address> \
        --robot.bbox=0.41,0.52,0.47,0.60 --policy.path=<checkpoint> ...

Backends: ``mujoco`` (the ``lego_pick`` twin; it designates a target brick per scene and can report its
projected box like ``bboxpick-collect`` does) and ``rtde`` (a real arm through ``ur_rtde``, an optional
extra). Every action passes the same ``SafetyLimits`` on both.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.cameras import CameraConfig
from lerobot.robots.config import RobotConfig

from lerobot_bboxpick.robots.ur5.safety import SafetyLimits
from lerobot_bboxpick.sim.layouts import check_setting

BACKENDS = ("mujoco", "rtde")
BBOX_SOURCES = ("oracle", "tracked")
BBOX_PICKERS = ("none", "web")


@RobotConfig.register_subclass("ur5")
@dataclass
class UR5Config(RobotConfig):
    """Options of the ``ur5`` robot (``--robot.<field>``)."""

    # "mujoco" (the lego_pick simulator) or "rtde" (a real UR5/UR5e through ur_rtde).
    backend: str = "mujoco"
    # Control rate of the actions (Hz); the datasets and policies use 20.
    fps: int = 20
    # The target on the first frame, normalised "x0,y0,x1,y1" (as observation.bbox). Unset: the web
    # picker (bbox_picker=web) or, in the simulator, the scene's designated target.
    bbox: str | None = None
    # "web": drag the box on the first frame in a browser page (the dashboard's picker); "none".
    bbox_picker: str = "none"
    # Port of the web picker's page on this machine (0: any free port); its URL is printed.
    bbox_picker_port: int = 0
    # Where observation.bbox comes from after the first frame: "tracked" (the colour tracker follows the
    # first box; the only choice on a real arm) or "oracle" (simulator only: the target's projected box
    # every frame, exactly as bboxpick-collect records it).
    bbox_source: str = "oracle"
    # Consecutive frames the tracker may lose the target before the arm is stopped (it then holds
    # still and ignores actions until a new target is given).
    max_lost_frames: int = 10
    safety: SafetyLimits = field(default_factory=SafetyLimits)
    # Stop the arm when no action arrives for this long (s).
    action_timeout_s: float = 0.5

    # --- mujoco backend
    # Scene layout (lerobot_bboxpick.sim.layouts.SETTINGS) and the first scene's seed; scene k uses
    # seed + k. Defaults to the first test seed (10000): recording demonstrations? use seed=0 (training).
    setting: str = "grid_id"
    seed: int = 10000
    # Wall-clock seconds a scene lasts from its first observation; a new scene starts on the next
    # observation after that. For lerobot-record use episode_time_s < scene_time_s <= episode_time_s +
    # reset_time_s, so every recorded episode starts on a fresh scene.
    scene_time_s: float = 10.0
    domain_randomization: bool = True

    # --- rtde backend
    host: str = "192.168.1.10"
    # 500 Hz on e-series (UR5e), 125 Hz on CB3 (UR5).
    servo_rate_hz: float = 500.0
    lookahead_time: float = 0.1
    gain: float = 300.0
    # Table frame in the arm's base frame: x, y, z (m) and a rotation vector (rad).
    base_from_table: list[float] = field(default_factory=lambda: [0.0] * 6)
    # TCP offset along the flange z axis (UMI's fingertips: 0.235 m).
    tcp_offset_m: float = 0.235
    # Gripper of the real arm: "robotiq_2f85" (URCap socket on the controller).
    gripper: str = "robotiq_2f85"
    # Camera and arm latencies are compensated where the chunks are, in the policy:
    # --policy.compensate_latency=true (--policy.camera_latency_s, --policy.action_latency_s).
    # Wrist camera (capture card) for the rtde backend, e.g.
    # --robot.cameras='{wrist: {type: opencv, index_or_path: 0, width: 1920, height: 1080, fps: 30}}'.
    # Frames are resized to height 224 and centre-cropped as UMI does. The mujoco backend renders its own.
    cameras: dict[str, CameraConfig] = field(default_factory=dict)

    def __post_init__(self) -> None:
        super().__post_init__()
        _one_of("backend", self.backend, BACKENDS)
        _one_of("bbox_source", self.bbox_source, BBOX_SOURCES)
        _one_of("bbox_picker", self.bbox_picker, BBOX_PICKERS)
        check_setting(self.setting)
        if self.backend == "rtde" and self.bbox_source == "oracle":
            # A real arm has no oracle: the default switches to the tracker.
            self.bbox_source = "tracked"
        if self.bbox is not None:
            parse_bbox(self.bbox)
        for name in ("fps", "scene_time_s", "action_timeout_s", "servo_rate_hz"):
            if not getattr(self, name) > 0:
                raise ValueError(f"robot.{name}={getattr(self, name)!r} must be > 0")
        if len(self.base_from_table) != 6:
            raise ValueError(
                f"robot.base_from_table={self.base_from_table} must be 6 numbers: x, y, z (m), "
                "rotation vector (rad)"
            )
        if self.backend == "rtde" and self.bbox is None and self.bbox_picker == "none":
            raise ValueError(
                "robot.backend=rtde needs the target: --robot.bbox=x0,y0,x1,y1 (normalised) or "
                "--robot.bbox_picker=web"
            )
        if self.backend == "rtde" and len(self.cameras) != 1:
            raise ValueError(
                "robot.backend=rtde needs exactly one wrist camera in --robot.cameras, e.g. "
                "'{wrist: {type: opencv, index_or_path: 0, width: 1920, height: 1080, fps: 30}}'"
            )


def _one_of(name: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ValueError(f"robot.{name}={value!r} is not one of: {', '.join(allowed)}")


def parse_bbox(text: str) -> list[float]:
    """``"x0,y0,x1,y1"`` -> four floats in [0, 1] with x1 > x0 and y1 > y0.

    Raises a ValueError naming ``robot.bbox`` otherwise."""
    try:
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        values = []
    if (
        len(values) != 4
        or not all(0.0 <= v <= 1.0 for v in values)
        or not (values[2] > values[0] and values[3] > values[1])
    ):
        raise ValueError(
            f"robot.bbox={text!r} must be 'x0,y0,x1,y1' normalised to [0, 1] with x1 > x0 and y1 > y0 "
            "(e.g. 0.41,0.52,0.47,0.60)"
        )
    return values
