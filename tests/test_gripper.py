"""Robotiq 2F-85 driver: the width <-> position mapping with clipping, and the ASCII protocol against a
stand-in of the URCap's socket server on 127.0.0.1 (loopback only, bounded loops, answers like the URCap:
``ack`` to SET, ``<VAR> <n>`` to GET)."""

from __future__ import annotations

import logging
import socket
import threading

import pytest

from lerobot_bboxpick.robots.ur5.gripper import (
    ROBOTIQ_2F85_STROKE_M,
    GripperError,
    Robotiq2F85,
    position_to_width,
    width_to_position,
)


class FakeRobotiqServer:
    """One-connection URCap stand-in: registers ACT/STA/GTO/POS/SPE/FOR; POS follows the request at once."""

    def __init__(self, activated: bool = False, answer: bool = True, reply_to_set: str = "ack") -> None:
        self.registers = {
            "ACT": int(activated),
            "STA": 3 * int(activated),
            "GTO": 0,
            "POS": 0,
            "SPE": 0,
            "FOR": 0,
        }
        self.lines: list[str] = []
        self.answer, self.reply_to_set = answer, reply_to_set
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(5.0)
        self.port = self._listener.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        try:
            conn, _ = self._listener.accept()
        except OSError:
            return
        with conn:
            conn.settimeout(5.0)
            buffer = b""
            for _ in range(10_000):  # bounded: a test never sends this many commands
                try:
                    data = conn.recv(1024)
                except OSError:
                    return
                if not data:
                    return
                buffer += data
                while b"\n" in buffer:
                    line, buffer = buffer.split(b"\n", 1)
                    reply = self._handle(line.decode("ascii"))
                    if self.answer:
                        conn.sendall(reply.encode("ascii"))

    def _handle(self, line: str) -> str:
        self.lines.append(line)
        words = line.split()
        if words[:1] == ["GET"] and len(words) == 2 and words[1] in self.registers:
            return f"{words[1]} {self.registers[words[1]]}"
        if words[:1] == ["SET"] and len(words) >= 3 and len(words) % 2 == 1:
            for name, value in zip(words[1::2], words[2::2], strict=True):
                self.registers[name] = int(value)
                if name == "ACT" and int(value) == 1:
                    self.registers["STA"] = 3  # activation completes at once here
            return self.reply_to_set
        return "?"

    def close(self) -> None:
        self._listener.close()
        self._thread.join(timeout=5.0)


@pytest.fixture
def server():
    s = FakeRobotiqServer()
    yield s
    s.close()


# ---------------------------------------------------------------------------- mapping
@pytest.mark.parametrize(
    ("width", "position"),
    [(0.085, 0), (0.0, 255), (0.0425, 128), (0.04, 135), (0.01, 225), (0.09, 0), (0.2, 0), (-0.01, 255)],
)
def test_width_to_position_is_linear_over_85_mm_and_clipped(width, position):
    assert width_to_position(width) == position


@pytest.mark.parametrize(
    ("position", "width"), [(0, 0.085), (255, 0.0), (51, 0.068), (300, 0.0), (-5, 0.085)]
)
def test_position_to_width(position, width):
    assert position_to_width(position) == pytest.approx(width, abs=1e-12)


def test_round_trip_error_is_at_most_half_a_step():
    half_step = ROBOTIQ_2F85_STROKE_M / 255 / 2  # 0.167 mm
    for i in range(0, 851):
        w = i * 1e-4
        assert abs(position_to_width(width_to_position(w)) - w) <= half_step + 1e-12


def test_calibrated_ends():
    # Fingers that touch at register 230 and open fully at 3.
    assert width_to_position(0.0, open_position=3, closed_position=230) == 230
    assert width_to_position(0.085, open_position=3, closed_position=230) == 3
    assert position_to_width(230, open_position=3, closed_position=230) == 0.0


# ---------------------------------------------------------------------------- protocol
def test_connect_activates_and_enables_motion(server):
    g = Robotiq2F85("127.0.0.1", server.port, speed=200, force=50)
    g.connect()
    try:
        assert server.lines == ["GET ACT", "SET ACT 1", "GET STA", "SET SPE 200", "SET FOR 50", "SET GTO 1"]
        assert server.registers["GTO"] == 1
    finally:
        g.disconnect()
    g.disconnect()  # safe twice


def test_connect_skips_activation_when_already_active():
    server = FakeRobotiqServer(activated=True)
    g = Robotiq2F85("127.0.0.1", server.port)
    try:
        g.connect()
        assert server.lines == ["GET ACT", "SET SPE 255", "SET FOR 100", "SET GTO 1"]
    finally:
        g.disconnect()
        server.close()


def test_set_width_and_width_round_trip(server, caplog):
    g = Robotiq2F85("127.0.0.1", server.port)
    g.connect()
    try:
        n = len(server.lines)
        g.set_width(0.04)
        assert server.lines[n:] == ["SET POS 135"]
        assert g.width() == pytest.approx(0.04, abs=ROBOTIQ_2F85_STROKE_M / 255 / 2)
        assert server.lines[-1] == "GET POS"
        g.set_width(0.04)  # same register: not re-sent
        assert server.lines[-1] == "GET POS"
        with caplog.at_level(logging.WARNING, logger="lerobot_bboxpick.robots.ur5.gripper"):
            g.set_width(0.09)  # UMI's widest: clipped to the 2F-85's 85 mm
            g.set_width(0.088)
        assert server.lines[-1] == "SET POS 0"
        assert g.width() == pytest.approx(0.085)
        assert sum("wider than" in r.getMessage() for r in caplog.records) == 1
        g.set_width(0.0)
        assert server.registers["POS"] == 255 and g.width() == 0.0
    finally:
        g.disconnect()


def test_refused_command_names_the_command():
    server = FakeRobotiqServer(activated=True, reply_to_set="?")
    g = Robotiq2F85("127.0.0.1", server.port)
    try:
        with pytest.raises(GripperError, match="'SET SPE 255'"):
            g.connect()
    finally:
        server.close()


def test_silent_gripper_times_out_with_the_address():
    server = FakeRobotiqServer(answer=False)
    g = Robotiq2F85("127.0.0.1", server.port, timeout_s=0.2)
    try:
        with pytest.raises(GripperError, match=rf"127\.0\.0\.1:{server.port}.*within 0\.2 s"):
            g.connect()
    finally:
        server.close()


def test_unreachable_gripper_names_the_urcap():
    with socket.create_server(("127.0.0.1", 0)) as s:
        port = s.getsockname()[1]
    g = Robotiq2F85("127.0.0.1", port, timeout_s=0.5)  # nothing listens there any more
    with pytest.raises(GripperError, match=rf"127\.0\.0\.1:{port}.*URCap"):
        g.connect()


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("speed", {"speed": 256}),
        ("force", {"force": -1}),
        ("closed_position", {"open_position": 10, "closed_position": 5}),
    ],
)
def test_bad_options_name_the_field(field, kwargs):
    with pytest.raises(ValueError, match=field):
        Robotiq2F85("127.0.0.1", **kwargs)
