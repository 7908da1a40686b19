"""``--teleop.type=bboxpick_expert``: the scripted expert as a LeRobot teleoperator (simulator only)."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.teleoperators.config import TeleoperatorConfig


@TeleoperatorConfig.register_subclass("bboxpick_expert")
@dataclass
class BboxpickExpertConfig(TeleoperatorConfig):
    """Options of the expert teleoperator (``--teleop.<field>``)."""

    # The --robot.id of the simulated ur5 to read; None: the only one connected in the process.
    robot_id: str | None = None
    # Re-plan from the arm's current state when get_action was not called for this long (s): the
    # expert takes over mid-episode (DAgger) from wherever the policy left the arm.
    takeover_gap_s: float = 0.2
    # Vary speed and approach offset per scene (seeded by the scene's seed), as bboxpick-collect does.
    vary: bool = True

    def __post_init__(self) -> None:
        if not self.takeover_gap_s > 0:
            raise ValueError(f"teleop.takeover_gap_s={self.takeover_gap_s!r} must be > 0")
