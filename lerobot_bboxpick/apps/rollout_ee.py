"""``bboxpick-rollout-ee``: ``lerobot-rollout`` where a person takes over the ``ur5`` with LeRobot's keyboard
or gamepad end-effector teleoperator (the DAgger strategy's human). LeRobot's CLI builds its rollout with
identity teleop processors and takes none from the command line; this entry point hands
``build_rollout_context`` (its public extension point) the same ``EEDeltaToPose10Step`` pipeline as
``bboxpick-record-ee``, so the teleoperator's deltas become the robot's absolute pose action. Every
``lerobot-rollout`` option works unchanged:

    bboxpick-rollout-ee --robot.type=ur5 --robot.backend=rtde ... --policy.path=<checkpoint> \\
        --strategy.type=dagger --teleop.type=keyboard_ee --dataset.repo_id=local/ur5_dagger ...
"""

import logging

from lerobot.rollout import RolloutConfig

# LeRobot's rollout CLI registers only some teleoperators; a person's end-effector ones are these.
from lerobot.teleoperators.gamepad import configuration_gamepad  # noqa: F401
from lerobot.teleoperators.keyboard import configuration_keyboard  # noqa: F401

from lerobot_bboxpick.apps.record_ee import ee_teleop_action_processor

log = logging.getLogger(__name__)


def rollout_ee(cfg: RolloutConfig) -> None:
    """LeRobot's rollout (``lerobot.scripts.lerobot_rollout.rollout``'s steps) with the delta step."""
    from lerobot.rollout import build_rollout_context, create_strategy
    from lerobot.utils.process import ProcessSignalHandler
    from lerobot.utils.utils import init_logging
    from lerobot.utils.visualization_utils import init_visualization, shutdown_visualization

    init_logging()
    if cfg.display_data:
        init_visualization(cfg.display_mode, session_name="rollout", ip=cfg.display_ip, port=cfg.display_port)
    shutdown_event = ProcessSignalHandler(use_threads=True, display_pid=False).shutdown_event
    ctx = build_rollout_context(cfg, shutdown_event, teleop_action_processor=ee_teleop_action_processor())
    strategy = create_strategy(cfg.strategy)
    steps = [type(step).__name__ for step in ctx.processors.teleop_action_processor.steps]
    log.info("rollout strategy %s, teleop actions through %s", cfg.strategy.type, steps)
    try:
        strategy.setup(ctx)
        strategy.run(ctx)
    except KeyboardInterrupt:
        log.info("interrupted by user")
    finally:
        strategy.teardown(ctx)  # stops the arm (the robot's disconnect)
        if cfg.display_data:
            shutdown_visualization(cfg.display_mode)


def main() -> None:
    """Entry point: LeRobot's rollout CLI (same options) with the end-effector delta step."""
    from lerobot.configs import parser
    from lerobot.scripts import lerobot_rollout  # noqa: F401  (registers LeRobot's robots and cameras)
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    parser.wrap()(rollout_ee)()


if __name__ == "__main__":
    main()
