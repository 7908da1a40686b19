"""What the ``ur5`` robot needs from an arm: the backend interface.

Two backends implement it: ``mujoco_backend.MujocoArm`` (the ``lego_pick`` twin, also what the tests
use) and ``rtde_backend.RtdeArm`` (a real UR5/UR5e through ``ur_rtde``). Poses are 4x4 TCP poses in the
table frame (the datasets' frame), widths in metres; the robot class checks every command against
``SafetyLimits`` before a backend sees it.
"""

from __future__ import annotations

import abc

import numpy as np


class ArmFault(RuntimeError):  # noqa: N818  (a "fault" is what UR calls it)
    """The arm stopped on its own (protective stop, emergency stop, lost connection); the message says
    what happened and how to recover."""


class ArmBackend(abc.ABC):
    """An arm with a gripper that follows absolute TCP targets sent at the control rate (20 Hz)."""

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the connection and hold the current pose."""

    @abc.abstractmethod
    def disconnect(self) -> None:
        """Stop the arm (it holds still) and close the connection; safe to call twice."""

    @property
    @abc.abstractmethod
    def is_connected(self) -> bool:
        """Whether ``connect`` succeeded and ``disconnect`` was not called since."""

    @abc.abstractmethod
    def tcp_pose(self) -> np.ndarray:
        """Measured TCP pose (4x4, table frame). Raises ``ArmFault`` if the arm has stopped itself."""

    @abc.abstractmethod
    def gripper_width(self) -> float:
        """Measured distance between the fingers (m)."""

    @abc.abstractmethod
    def command(self, T: np.ndarray, width: float) -> None:
        """Move toward TCP pose ``T`` (already checked and speed-limited) and gripper ``width``.

        Raises ``ArmFault`` if the arm has stopped itself.
        """

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop moving now and hold the current pose (Ctrl-C, a lost track, an action timeout)."""
