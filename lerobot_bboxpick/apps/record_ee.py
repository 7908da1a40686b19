"""``bboxpick-record-ee``: ``lerobot-record`` for a person driving the ``ur5`` with LeRobot's keyboard or
gamepad end-effector teleoperator. It is LeRobot's own ``record`` with one teleop-action processor step
(``EEDeltaToPose10Step``) that turns the teleoperator's deltas into the robot's absolute pose action;
every ``lerobot-record`` option works unchanged:

    bboxpick-record-ee --robot.type=ur5 --robot.backend=rtde ... --teleop.type=keyboard_ee \\
        --dataset.repo_id=local/ur5_keyboard --dataset.fps=20 --dataset.single_task="pick up the block"
"""

from __future__ import annotations

from lerobot.processor import RobotProcessorPipeline
from lerobot.processor.converters import robot_action_observation_to_transition, transition_to_robot_action

# lerobot-record registers the keyboard teleoperators; the gamepad's config must be imported too.
from lerobot.teleoperators.gamepad import configuration_gamepad  # noqa: F401

from lerobot_bboxpick.robots.ur5.processor_ee_delta import EEDeltaToPose10Step


def ee_teleop_action_processor(step_m: float = 0.01) -> RobotProcessorPipeline:
    """The teleop-action pipeline (teleoperator deltas, robot observation) -> ur5 action."""
    return RobotProcessorPipeline(
        steps=[EEDeltaToPose10Step(step_m=step_m)],
        to_transition=robot_action_observation_to_transition,
        to_output=transition_to_robot_action,
    )


def main() -> None:
    """Entry point: LeRobot's record CLI with the end-effector delta step."""
    from lerobot.scripts.lerobot_record import record
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    record(teleop_action_processor=ee_teleop_action_processor())


if __name__ == "__main__":
    main()
