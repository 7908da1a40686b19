"""LeRobot robots contributed by lerobot_bboxpick (``--robot.type=ur5``)."""
