"""Grippers of the real arm: the ``Gripper`` interface and a Robotiq 2F-85 driver.

Why the Robotiq 2F-85: it is the most common parallel gripper on UR arms (sold through UR+), its URCap
runs a small ASCII socket server on the controller (port 63352) that a plain TCP socket can drive, so
it needs no extra Python dependency, and that URCap is already installed on most UR cells that own
one. Protocol (one command per line, each answered): ``SET ACT 1`` (activate), ``SET GTO 1`` (follow
the requested position), ``SET POS n`` / ``SET SPE n`` / ``SET FOR n`` (n in 0..255) answered ``ack``;
``GET POS`` answered ``POS n``. Position 0 is fully open (85 mm between the fingers), 255 fully closed.

Widths map linearly to positions over the stroke ``0..0.085 m``. Our datasets (UMI's gripper) go up
to 0.09 m: wider requests are clipped to the 2F-85's 0.085 m (a warning is logged once per gripper).
The real finger travel is close to, not exactly, linear in the position register; calibrate
``open_position`` / ``closed_position`` if your fingers stop short of the ends.
"""

from __future__ import annotations

import abc
import logging
import socket
import time

log = logging.getLogger(__name__)

ROBOTIQ_PORT = 63352
ROBOTIQ_2F85_STROKE_M = 0.085
_POSITION_MAX = 255


class GripperError(RuntimeError):
    """The gripper refused a command, did not answer, or cannot be reached."""


class Gripper(abc.ABC):
    """A parallel gripper commanded by the distance between its fingers (m)."""

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the connection and make the gripper ready to move."""

    @abc.abstractmethod
    def disconnect(self) -> None:
        """Close the connection; safe to call twice."""

    @abc.abstractmethod
    def width(self) -> float:
        """Measured distance between the fingers (m)."""

    @abc.abstractmethod
    def set_width(self, width_m: float) -> None:
        """Move the fingers toward ``width_m`` (m); returns without waiting for the motion."""


def width_to_position(
    width_m: float,
    stroke_m: float = ROBOTIQ_2F85_STROKE_M,
    open_position: int = 0,
    closed_position: int = 255,
) -> int:
    """Robotiq position register (``open_position`` at ``stroke_m``, ``closed_position`` at 0 m) for a
    width, linear in between; widths outside ``[0, stroke_m]`` are clipped first."""
    w = min(max(float(width_m), 0.0), stroke_m)
    return int(round(closed_position + (open_position - closed_position) * w / stroke_m))


def position_to_width(
    position: int, stroke_m: float = ROBOTIQ_2F85_STROKE_M, open_position: int = 0, closed_position: int = 255
) -> float:
    """Inverse of :func:`width_to_position`; positions past the calibrated ends clip to 0 / ``stroke_m``."""
    fraction = (closed_position - float(position)) / (closed_position - open_position)
    return min(max(fraction, 0.0), 1.0) * stroke_m


class Robotiq2F85(Gripper):
    """Robotiq 2F-85 through its URCap's socket server on the UR controller (``host:63352``)."""

    def __init__(
        self,
        host: str,
        port: int = ROBOTIQ_PORT,
        speed: int = 255,
        force: int = 100,
        open_position: int = 0,
        closed_position: int = 255,
        timeout_s: float = 2.0,
        activation_timeout_s: float = 10.0,
    ) -> None:
        """``speed`` / ``force`` are register values 0..255; ``open_position`` / ``closed_position`` the
        registers at the full 85 mm and at 0 mm (0 and 255 unless calibrated); ``timeout_s`` bounds every
        answer, ``activation_timeout_s`` the first activation (the fingers open and close once)."""
        for name, value in (
            ("speed", speed),
            ("force", force),
            ("open_position", open_position),
            ("closed_position", closed_position),
        ):
            if not (isinstance(value, int) and 0 <= value <= _POSITION_MAX):
                raise ValueError(f"Robotiq2F85 {name}={value!r} must be an integer in 0..255")
        if not closed_position > open_position:
            raise ValueError(
                f"Robotiq2F85 closed_position={closed_position} must be > open_position={open_position}"
            )
        if not (timeout_s > 0 and activation_timeout_s > 0):
            raise ValueError(
                f"Robotiq2F85 timeout_s={timeout_s!r} and activation_timeout_s={activation_timeout_s!r} "
                "must be > 0"
            )
        self.host, self.port = host, port
        self.speed, self.force = speed, force
        self.open_position, self.closed_position = open_position, closed_position
        self.timeout_s, self.activation_timeout_s = timeout_s, activation_timeout_s
        self._sock: socket.socket | None = None
        self._last_position: int | None = None
        self._warned_clip = False

    # ------------------------------------------------------------------ Gripper
    def connect(self) -> None:
        """Connect to the URCap, activate the gripper if needed (the fingers move!), enable motion."""
        if self._sock is not None:
            return
        try:
            self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        except OSError as e:
            raise GripperError(
                f"cannot reach the Robotiq gripper at {self.host}:{self.port} ({e}); is the Robotiq URCap "
                "installed and its gripper activated in the installation (Installation > URCaps > Gripper)?"
            ) from e
        try:
            if self._get("ACT") != 1:
                self._set("ACT", 1)
                self._wait_activated()
            self._set("SPE", self.speed)
            self._set("FOR", self.force)
            self._set("GTO", 1)
        except BaseException:
            self.disconnect()
            raise

    def disconnect(self) -> None:
        """Close the socket (the gripper keeps its last position)."""
        sock, self._sock = self._sock, None
        self._last_position = None
        if sock is not None:
            sock.close()

    def width(self) -> float:
        """Measured width from ``GET POS`` (m)."""
        return position_to_width(
            self._get("POS"), ROBOTIQ_2F85_STROKE_M, self.open_position, self.closed_position
        )

    def set_width(self, width_m: float) -> None:
        """``SET POS n`` for ``width_m`` clipped to ``[0, 0.085]`` m; repeated positions are not re-sent."""
        if width_m > ROBOTIQ_2F85_STROKE_M and not self._warned_clip:
            self._warned_clip = True
            log.warning(
                "gripper width %.4f m is wider than the Robotiq 2F-85's %.3f m stroke: clipped (logged once)",
                width_m,
                ROBOTIQ_2F85_STROKE_M,
            )
        position = width_to_position(width_m, ROBOTIQ_2F85_STROKE_M, self.open_position, self.closed_position)
        if position != self._last_position:
            self._set("POS", position)
            self._last_position = position

    # ------------------------------------------------------------------ protocol
    def _wait_activated(self) -> None:
        # Activation runs a full open/close cycle; STA = 3 means "activation completed".
        deadline = time.monotonic() + self.activation_timeout_s
        while self._get("STA") != 3:
            if time.monotonic() > deadline:
                raise GripperError(
                    f"the Robotiq gripper at {self.host}:{self.port} did not finish activating within "
                    f"{self.activation_timeout_s} s (GET STA never reached 3); check its power and cable"
                )
            time.sleep(0.05)

    def _set(self, name: str, value: int) -> None:
        reply = self._ask(f"SET {name} {value}")
        if reply != "ack":
            raise GripperError(
                f"the Robotiq gripper answered {reply!r} to 'SET {name} {value}' (expected 'ack')"
            )

    def _get(self, name: str) -> int:
        reply = self._ask(f"GET {name}")
        parts = reply.split()
        if len(parts) != 2 or parts[0] != name or not parts[1].lstrip("-").isdigit():
            raise GripperError(
                f"the Robotiq gripper answered {reply!r} to 'GET {name}' (expected '{name} <n>')"
            )
        return int(parts[1])

    def _ask(self, command: str) -> str:
        if self._sock is None:
            raise GripperError("the Robotiq gripper is not connected: call connect() first")
        try:
            self._sock.sendall(f"{command}\n".encode("ascii"))
            # Each answer is one short token ("ack", "POS 12"), with or without a trailing newline.
            data = self._sock.recv(1024)
        except OSError as e:  # includes socket.timeout
            raise GripperError(
                f"no answer from the Robotiq gripper at {self.host}:{self.port} to {command!r} within "
                f"{self.timeout_s} s ({e})"
            ) from e
        if not data:
            raise GripperError(f"the Robotiq gripper at {self.host}:{self.port} closed the connection")
        return data.decode("ascii", errors="replace").strip()
