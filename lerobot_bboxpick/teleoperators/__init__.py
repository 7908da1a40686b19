"""LeRobot teleoperators contributed by lerobot_bboxpick (``--teleop.type=bboxpick_expert``)."""
