"""RtdeArm against in-process stand-ins of ur_rtde's RTDEControlInterface, RTDEReceiveInterface and
DashboardClient: servo rate, interpolation, speed bound, action timeout, stop sequence, protective /
emergency stops, thread failures and the table <-> base frame conversion, with numbers.

The stand-ins keep ur_rtde's real semantics where the backend depends on them: ``initPeriod`` returns a
``timedelta`` of the steady clock and ``waitPeriod(t)`` sleeps until ``t + 1/frequency`` with the
frequency given to the constructor (so a rate test fails if the backend passes the wrong frequency or
skips ``initPeriod``/``waitPeriod``); ``servoL`` moves the simulated TCP a first-order step toward its
target and returns False once the script stopped; a protective stop freezes the TCP until the
dashboard unlocks it. Times come from ``time.monotonic`` (the backend's clock).
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from datetime import timedelta

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lerobot_bboxpick.robots.ur5.backend import ArmFault
from lerobot_bboxpick.robots.ur5.gripper import Gripper
from lerobot_bboxpick.robots.ur5.rtde_backend import (
    INSTALL_HINT,
    PoseSchedule,
    RtdeArm,
    RtdeSettings,
    default_control_factory,
    default_dashboard_factory,
    default_receive_factory,
    make_rtde_arm,
    mat_to_pose6,
    pose6_to_mat,
)

# Start pose of the simulated TCP in the base frame (tool pointing down, angle < pi: unique rotvec).
START_POSE6 = [0.45, -0.10, 0.30, 2.2, -2.2, 0.05]


def _mat(pose6) -> np.ndarray:
    """Independent of the code under test: scipy only."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(pose6[3:]).as_matrix()
    T[:3, 3] = pose6[:3]
    return T


def _angle(R: np.ndarray) -> float:
    return float(np.linalg.norm(Rotation.from_matrix(R).as_rotvec()))


# ---------------------------------------------------------------------------- stand-ins
class FakeUR:
    """The controller side shared by the three stand-ins: TCP state, stop flags, a timestamped call log."""

    def __init__(self, pose6=START_POSE6) -> None:
        self.lock = threading.Lock()
        self.calls: list[tuple[float, str, tuple]] = []
        self.actual = _mat(pose6)
        self.protective = False
        self.emergency = False
        self.script_running = True
        self.fail_reads_with: Exception | None = None
        self.first_stop_read: float | None = None  # time the first True stop flag was read

    def log(self, name: str, *args) -> None:
        with self.lock:
            self.calls.append((time.monotonic(), name, args))

    def times(self, name: str) -> np.ndarray:
        with self.lock:
            return np.array([t for t, n, _ in self.calls if n == name])

    def args(self, name: str) -> list[tuple]:
        with self.lock:
            return [a for _, n, a in self.calls if n == name]

    def servo_poses(self, after: float = -np.inf) -> tuple[np.ndarray, list[np.ndarray]]:
        with self.lock:
            rows = [(t, a[0]) for t, n, a in self.calls if n == "servoL" and t >= after]
        return np.array([t for t, _ in rows]), [_mat(p) for _, p in rows]

    def names(self) -> list[str]:
        with self.lock:
            return [n for _, n, _ in self.calls]

    def follow(self, pose6, t: float, lookahead: float) -> None:
        """First-order tracking of a servoL target: a fraction t / lookahead of the way per call."""
        target, f = _mat(pose6), min(1.0, t / lookahead)
        with self.lock:
            A = self.actual
            self.actual = np.eye(4)
            self.actual[:3, 3] = A[:3, 3] + f * (target[:3, 3] - A[:3, 3])
            rv = Rotation.from_matrix(A[:3, :3].T @ target[:3, :3]).as_rotvec()
            self.actual[:3, :3] = A[:3, :3] @ Rotation.from_rotvec(f * rv).as_matrix()


class FakeControl:
    """Stand-in of rtde_control.RTDEControlInterface(hostname, frequency)."""

    def __init__(self, ur: FakeUR, hostname: str, frequency: float = -1.0) -> None:
        self.ur, self.period = ur, 1.0 / (frequency if frequency > 0 else 500.0)
        ur.log("control.__init__", hostname, frequency)

    def initPeriod(self) -> timedelta:  # noqa: N802
        return timedelta(seconds=time.monotonic())

    def waitPeriod(self, t_cycle_start: timedelta) -> None:  # noqa: N802
        self.ur.log("waitPeriod", t_cycle_start.total_seconds())
        end = t_cycle_start.total_seconds() + self.period
        remaining = end - time.monotonic()
        if remaining > 3e-4:
            time.sleep(remaining - 2e-4)
        while time.monotonic() < end:  # the last 0.2 ms: spin, as ur_rtde does, for an exact period
            pass

    def servoL(self, pose, speed, acceleration, t, lookahead_time, gain) -> bool:  # noqa: N802
        self.ur.log("servoL", list(pose), speed, acceleration, t, lookahead_time, gain)
        # Refused only once the script stopped; during a stop the backend must notice the flags itself.
        if not self.ur.script_running:
            return False
        if self.ur.protective or self.ur.emergency:
            return True  # accepted but the arm does not move
        self.ur.follow(pose, t, lookahead_time)
        return True

    def servoStop(self, a: float = 10.0) -> bool:  # noqa: N802
        self.ur.log("servoStop", a)
        return True

    def setTcp(self, tcp_offset) -> bool:  # noqa: N802
        self.ur.log("setTcp", list(tcp_offset))
        return True

    def setWatchdog(self, min_frequency: float = 10.0) -> bool:  # noqa: N802
        self.ur.log("setWatchdog", min_frequency)
        return True

    def kickWatchdog(self) -> bool:  # noqa: N802
        self.ur.log("kickWatchdog")
        return True

    def stopScript(self) -> None:  # noqa: N802
        self.ur.log("stopScript")
        self.ur.script_running = False

    def reuploadScript(self) -> bool:  # noqa: N802
        self.ur.log("reuploadScript")
        self.ur.script_running = True
        return True

    def isConnected(self) -> bool:  # noqa: N802
        return True

    def reconnect(self) -> bool:
        self.ur.log("control.reconnect")
        return True

    def disconnect(self) -> None:
        self.ur.log("control.disconnect")


class FakeReceive:
    """Stand-in of rtde_receive.RTDEReceiveInterface(hostname, frequency)."""

    def __init__(self, ur: FakeUR, hostname: str, frequency: float = -1.0) -> None:
        self.ur = ur
        ur.log("receive.__init__", hostname, frequency)

    def getActualTCPPose(self) -> list[float]:  # noqa: N802
        if self.ur.fail_reads_with is not None:
            raise self.ur.fail_reads_with
        with self.ur.lock:
            T = self.ur.actual.copy()
        return [*T[:3, 3], *Rotation.from_matrix(T[:3, :3]).as_rotvec()]

    def _flag(self, value: bool) -> bool:
        if value and self.ur.first_stop_read is None:
            self.ur.first_stop_read = time.monotonic()
        return value

    def isProtectiveStopped(self) -> bool:  # noqa: N802
        return self._flag(self.ur.protective)

    def isEmergencyStopped(self) -> bool:  # noqa: N802
        return self._flag(self.ur.emergency)

    def isConnected(self) -> bool:  # noqa: N802
        return True

    def disconnect(self) -> None:
        self.ur.log("receive.disconnect")


class FakeDashboard:
    """Stand-in of dashboard_client.DashboardClient(hostname)."""

    def __init__(self, ur: FakeUR, hostname: str) -> None:
        self.ur = ur

    def connect(self, timeout_ms: int = 2000) -> None:
        self.ur.log("dashboard.connect")

    def closeSafetyPopup(self) -> None:  # noqa: N802
        self.ur.log("dashboard.closeSafetyPopup")

    def unlockProtectiveStop(self) -> None:  # noqa: N802
        self.ur.log("dashboard.unlockProtectiveStop")
        self.ur.protective = False
        self.ur.script_running = False  # a protective stop ends the control script

    def disconnect(self) -> None:
        self.ur.log("dashboard.disconnect")


class FakeGripper(Gripper):
    """A gripper that reaches its width at once."""

    def __init__(self, ur: FakeUR) -> None:
        self.ur, self._width = ur, 0.08

    def connect(self) -> None:
        self.ur.log("gripper.connect")

    def disconnect(self) -> None:
        self.ur.log("gripper.disconnect")

    def width(self) -> float:
        return self._width

    def set_width(self, width_m: float) -> None:
        self._width = width_m


def make_arm(ur: FakeUR, **settings) -> RtdeArm:
    """An RtdeArm wired to the stand-ins (CB3 rate unless told)."""
    settings.setdefault("servo_hz", 125.0)
    return RtdeArm(
        RtdeSettings(host="ur-fake", **settings),
        FakeGripper(ur),
        control_factory=lambda host, hz: FakeControl(ur, host, hz),
        receive_factory=lambda host, hz: FakeReceive(ur, host, hz),
        dashboard_factory=lambda host: FakeDashboard(ur, host),
    )


def stream(arm: RtdeArm, T, seconds: float, hz: float = 20.0, width: float = 0.05) -> tuple[float, float]:
    """Call ``command`` at ``hz`` for ``seconds`` (T may be a function of the step); returns the times just
    before and just after the last call."""
    t0, k = time.monotonic(), 0
    before = after = t0
    while time.monotonic() - t0 < seconds:
        before = time.monotonic()
        arm.command(T(k) if callable(T) else T, width)
        after = time.monotonic()
        k += 1
        time.sleep(max(0.0, t0 + k / hz - time.monotonic()))
    return before, after


@pytest.fixture
def ur():
    return FakeUR()


@pytest.fixture
def arms():
    """Arms to disconnect at the end of a test, whatever happened."""
    made: list[RtdeArm] = []
    yield made
    for arm in made:
        arm.disconnect()


def connected(arms: list[RtdeArm], ur: FakeUR, **settings) -> RtdeArm:
    arm = make_arm(ur, **settings)
    arm.connect()
    arms.append(arm)
    return arm


# ---------------------------------------------------------------------------- rate
@pytest.mark.parametrize("hz", [125.0, 500.0])
def test_servo_rate_matches_the_arm(ur, arms, hz):
    arm = connected(arms, ur, servo_hz=hz)
    hold = arm.tcp_pose()
    t0 = time.monotonic()
    stream(arm, hold, 1.5)
    times = ur.times("servoL")
    window = times[(times >= t0 + 0.2) & (times <= t0 + 1.5)]
    assert window[-1] - window[0] >= 1.0
    # servoL calls per second over >= 1 s. The backend ticks on a grid of cycle starts given to waitPeriod
    # and catches up late ticks, so jitter does not change the count; a stall of more than 5 ticks (the
    # shared machine took the CPU away) restarts the grid, visible as a jump in the waitPeriod arguments:
    # that lost time is left out, and must stay a minority.
    grid = np.array([a[0] for a in ur.args("waitPeriod")])
    grid = grid[(grid >= window[0]) & (grid <= window[-1])]
    jumps = np.diff(grid)
    lost = float(np.sum(jumps[jumps > 5.5 / hz] - 1.0 / hz))  # a restart jumps > 6 periods
    rate = (len(window) - 1) / (window[-1] - window[0] - lost)
    assert abs(rate - hz) <= 0.1 * hz, (
        f"servoL rate {rate:.1f} Hz ({lost:.3f} s lost to stalls), expected {hz}"
    )
    assert window[-1] - window[0] - lost >= 0.5, f"the control thread stalled {lost:.2f} s of the window"
    assert ur.args("control.__init__") == [("ur-fake", hz)]
    assert ur.args("setWatchdog") == [(10.0,)]
    # The watchdog is kicked every tick.
    kicks = ur.times("kickWatchdog")
    assert abs(np.sum((kicks >= window[0]) & (kicks <= window[-1])) - len(window)) <= 2


# ---------------------------------------------------------------------------- interpolation
def test_interpolation_is_a_straight_line_and_slerp_reaching_the_target_on_time(ur, arms):
    hz, delay = 125.0, 0.4
    arm = connected(arms, ur, servo_hz=hz, action_latency_s=delay - 0.05, action_timeout_s=3.0)
    T0 = arm.tcp_pose()
    stream(arm, T0, 0.2)
    time.sleep(delay + 0.1)  # let the schedule of those holds run out: P1's segment then starts at arrival
    T1 = T0.copy()
    T1[:3, 3] += [0.02, -0.01, 0.015]  # 27 mm in 0.4 s: 14 % of the speed bound
    T1[:3, :3] = T0[:3, :3] @ Rotation.from_rotvec([0.03, 0.04, -0.02]).as_matrix()
    before = time.monotonic()
    arm.command(T1, 0.05)
    after = time.monotonic()
    time.sleep(delay + 0.25)

    times, poses = ur.servo_poses(after=before)
    d = T1[:3, 3] - T0[:3, 3]
    rv = Rotation.from_matrix(T0[:3, :3].T @ T1[:3, :3]).as_rotvec()
    alphas = []
    for P in poses:
        alpha = float((P[:3, 3] - T0[:3, 3]) @ d / (d @ d))
        off_line = np.linalg.norm(P[:3, 3] - (T0[:3, 3] + alpha * d))
        assert off_line < 1e-9, f"servoL position {off_line:.2e} m off the straight line"
        R_slerp = T0[:3, :3] @ Rotation.from_rotvec(alpha * rv).as_matrix()
        assert np.abs(P[:3, :3] - R_slerp).max() < 1e-9, "rotation is not the slerp at the same fraction"
        alphas.append(alpha)
    alphas = np.array(alphas)
    assert alphas.min() > -1e-9 and alphas.max() < 1 + 1e-9
    assert np.all(np.diff(alphas) > -1e-12), "the path went backwards"
    # ~40 ticks nominally; a machine under load may run fewer, enough to check the line.
    assert np.sum((alphas > 0.05) & (alphas < 0.95)) >= 10, "too few ticks between the two targets"
    reached = np.flatnonzero(np.abs(alphas - 1) < 1e-9)
    k = reached[0]
    assert np.all(np.abs(alphas[k:] - 1) < 1e-9), "the target was not held after reaching it"
    # Due at arrival + delay with arrival in [before, after]: the target is sent first by the first tick
    # at or after that time (the tick before it still interpolates): reached within one tick.
    assert times[k] >= before + delay
    assert times[k - 1] < after + delay + 0.005
    assert times[k] - (after + delay) < 1 / hz + 0.05


def test_steps_never_exceed_the_speed_bounds(ur, arms):
    hz, v_max, w_max = 125.0, 0.25, 0.5
    arm = connected(arms, ur, servo_hz=hz, max_pos_speed=v_max, max_rot_speed=w_max, action_timeout_s=3.0)
    T0 = arm.tcp_pose()
    T1 = T0.copy()
    T1[:3, 3] += [0.12, 0.09, 0.0]  # 0.15 m: 0.6 s at 0.25 m/s, asked for in one 50 ms command period
    T1[:3, :3] = T0[:3, :3] @ Rotation.from_rotvec([0.0, 0.0, 0.25]).as_matrix()  # 0.5 s at 0.5 rad/s
    t0 = time.monotonic()
    stream(arm, T1, 1.0)
    for _ in range(40):  # a loaded machine drops ticks, and each tick moves at most the bound: wait <= 2 s
        if np.abs(ur.servo_poses(after=t0)[1][-1] - T1).max() < 1e-9:
            break
        time.sleep(0.05)
    times, poses = ur.servo_poses(after=t0)
    steps = [np.linalg.norm(B[:3, 3] - A[:3, 3]) for A, B in zip(poses, poses[1:], strict=False)]
    turns = [_angle(A[:3, :3].T @ B[:3, :3]) for A, B in zip(poses, poses[1:], strict=False)]
    assert max(steps) <= v_max / hz + 1e-12, f"step {max(steps):.6f} m > {v_max / hz:.6f} m per tick"
    assert max(turns) <= w_max / hz + 1e-9
    assert max(steps) > 0.9 * v_max / hz, "the bound never bound: the test moved too little"
    k = next(i for i, P in enumerate(poses) if np.abs(P - T1).max() < 1e-9)
    assert times[k] - t0 >= 0.15 / v_max - 1 / hz, "reached faster than the speed bound allows"
    assert np.abs(poses[-1] - T1).max() < 1e-9


def test_pose_schedule_replaces_the_rest_and_stretches_to_the_speed_bound():
    T0 = np.eye(4)
    A, B, C = (np.eye(4) for _ in range(3))
    A[:3, 3], B[:3, 3], C[:3, 3] = [0.01, 0, 0], [0.02, 0, 0], [0.0, 0.05, 0]
    s = PoseSchedule(0.0, T0)
    assert s.insert(0.0, 0.05, A, 1.0, 1.0) == pytest.approx(0.05)
    assert s.insert(0.01, 0.10, B, 1.0, 1.0) == pytest.approx(0.10)
    assert s.at(0.075)[:3, 3] == pytest.approx([0.015, 0, 0])
    # A target due before B replaces B: the schedule is now, A (kept, due 0.05 < 0.06), C.
    assert s.insert(0.02, 0.06, C, 10.0, 1.0) == pytest.approx(0.06)
    assert s.times == pytest.approx([0.02, 0.05, 0.06])
    assert s.at(0.02)[:3, 3] == pytest.approx([0.004, 0, 0])  # where the old schedule was at 0.02
    # Late target (due already passed): leaves from the pose at now, as fast as allowed (0.1 m/s).
    assert s.insert(0.5, 0.4, A, 0.1, 1.0) == pytest.approx(0.5 + np.linalg.norm([0.01, -0.05, 0]) / 0.1)
    assert s.at(10.0)[:3, 3] == pytest.approx([0.01, 0, 0])


# ---------------------------------------------------------------------------- action timeout
def test_action_timeout_stops_the_arm_and_resumes_from_the_measured_pose(ur, arms, caplog):
    hz, timeout = 125.0, 0.3
    arm = connected(arms, ur, servo_hz=hz, action_timeout_s=timeout)
    T0 = arm.tcp_pose()

    def ramp(k: int) -> np.ndarray:  # 0.1 m/s along x: the simulated TCP trails the command
        T = T0.copy()
        T[0, 3] += 0.005 * k
        return T

    with caplog.at_level(logging.WARNING, logger="lerobot_bboxpick.robots.ur5.rtde_backend"):
        before, after = stream(arm, ramp, 0.5)
        time.sleep(timeout + 0.3)
    stops = ur.times("servoStop")
    assert len(stops) == 1
    assert stops[0] >= before + timeout
    # Within 2 ticks of the timeout: at most 2 control ticks ran between the deadline and the servoStop
    # (counting ticks, not seconds, so a machine that stalls the thread does not fail the test).
    ticks = ur.times("waitPeriod")
    late_ticks = np.sum((ticks > after + timeout) & (ticks < stops[0]))
    assert late_ticks <= 2, f"servoStop came {late_ticks} ticks after the action timeout"
    assert stops[0] <= after + timeout + 0.5  # gross bound
    servo_t, servo_poses = ur.servo_poses()
    assert servo_t[-1] < stops[0], "servoL after servoStop"
    kicks = ur.times("kickWatchdog")
    assert np.sum(kicks > stops[0]) > 0.5 * 0.3 * hz, "the watchdog must still be kicked while holding"
    assert any("no command for" in r.getMessage() for r in caplog.records)

    # The next command resumes from where the arm is, not from the last pose sent: move the simulated
    # TCP 8 mm away while it holds (as a decelerating or hand-guided arm would be elsewhere).
    with ur.lock:
        ur.actual[1, 3] += 0.008
        measured = ur.actual.copy()
    assert np.linalg.norm(servo_poses[-1][:3, 3] - measured[:3, 3]) > 0.007
    t_resume = time.monotonic()
    stream(arm, ramp(100), 0.2)
    _, resumed = ur.servo_poses(after=t_resume)
    assert np.abs(resumed[0] - measured).max() < 1e-9
    assert len(ur.times("servoStop")) == 1


# ---------------------------------------------------------------------------- stop and disconnect
def test_stop_holds_and_the_next_command_resumes(ur, arms):
    arm = connected(arms, ur)
    stream(arm, arm.tcp_pose(), 0.3)
    arm.stop()
    returned = time.monotonic()
    stops = ur.times("servoStop")
    assert len(stops) == 1 and stops[0] <= returned
    arm.stop()  # idempotent
    time.sleep(0.2)
    assert len(ur.times("servoStop")) == 1
    assert ur.times("servoL")[-1] < stops[0]
    assert np.sum(ur.times("kickWatchdog") > returned) > 10
    stream(arm, arm.tcp_pose(), 0.2)
    assert ur.times("servoL")[-1] > returned


def test_disconnect_runs_the_stop_sequence_in_order_once(ur, arms):
    arm = connected(arms, ur)
    stream(arm, arm.tcp_pose(), 0.3)
    n_before = len(ur.names())
    arm.disconnect()
    tail = [n for n in ur.names()[n_before:] if n not in ("servoL", "kickWatchdog", "waitPeriod")]
    assert tail == [
        "servoStop",
        "stopScript",
        "control.disconnect",
        "receive.disconnect",
        "gripper.disconnect",
    ]
    assert ur.args("servoStop") == [(10.0,)]
    assert ur.times("servoL")[-1] < ur.times("servoStop")[0]
    assert not arm.is_connected
    n_after = len(ur.names())
    arm.disconnect()
    assert len(ur.names()) == n_after, "a second disconnect must do nothing"
    with pytest.raises(RuntimeError, match="connect"):
        arm.command(np.eye(4), 0.05)


# ---------------------------------------------------------------------------- protective / emergency stop
def test_protective_stop_raises_with_the_recovery_and_recovers(ur, arms):
    arm = connected(arms, ur)
    stream(arm, arm.tcp_pose(), 0.3)
    t_flip = time.monotonic()
    ur.protective = True
    time.sleep(0.1)
    with pytest.raises(ArmFault, match="protective stop") as err:
        arm.command(np.eye(4), 0.05)
    for step in ("recover_protective_stop", "closeSafetyPopup", "unlockProtectiveStop", "reuploadScript"):
        assert step in str(err.value)
    with pytest.raises(ArmFault, match="protective stop"):
        arm.tcp_pose()
    servo_t = ur.times("servoL")
    assert ur.first_stop_read is not None and servo_t[-1] < ur.first_stop_read, "servoL after the stop"
    assert np.sum(servo_t > t_flip) <= 1  # at most the one tick that read the flag just before the flip

    n_before = len(ur.names())
    arm.recover_protective_stop()
    steps = [n for n in ur.names()[n_before:] if n not in ("kickWatchdog", "servoL", "waitPeriod")]
    assert steps[:7] == [
        "dashboard.connect",
        "dashboard.closeSafetyPopup",
        "dashboard.unlockProtectiveStop",
        "dashboard.disconnect",
        "reuploadScript",
        "setTcp",
        "setWatchdog",
    ]
    t_resume = time.monotonic()
    stream(arm, arm.tcp_pose(), 0.2)
    assert np.sum(ur.times("servoL") > t_resume) > 10


def test_emergency_stop_raises_and_cannot_be_unlocked_by_software(ur, arms):
    arm = connected(arms, ur)
    stream(arm, arm.tcp_pose(), 0.2)
    ur.emergency = True
    time.sleep(0.1)
    with pytest.raises(ArmFault, match="emergency-stop"):
        arm.command(np.eye(4), 0.05)
    with pytest.raises(ArmFault, match="emergency"):
        arm.recover_protective_stop()
    assert ur.times("servoL")[-1] < ur.first_stop_read
    assert "dashboard.unlockProtectiveStop" not in ur.names()


def test_a_stopped_control_script_is_a_fault(ur, arms):
    arm = connected(arms, ur)
    stream(arm, arm.tcp_pose(), 0.2)
    ur.script_running = False  # e.g. stopped from the pendant, or the watchdog expired
    time.sleep(0.1)
    with pytest.raises(ArmFault, match="servoL was refused"):
        arm.command(np.eye(4), 0.05)
    n = len(ur.times("servoL"))
    time.sleep(0.1)
    assert len(ur.times("servoL")) == n, "servoL after the refusal"


def test_connect_refuses_a_protective_stopped_arm(ur):
    ur.protective = True
    arm = make_arm(ur)
    with pytest.raises(ArmFault, match="recover_protective_stop"):
        arm.connect()
    assert not arm.is_connected
    assert "control.disconnect" in ur.names() and "receive.disconnect" in ur.names()


def test_an_exception_in_the_thread_surfaces_as_arm_fault(ur, arms):
    arm = connected(arms, ur)
    stream(arm, arm.tcp_pose(), 0.2)
    ur.fail_reads_with = RuntimeError("boom: RTDE receive link lost")
    time.sleep(0.1)
    with pytest.raises(ArmFault, match="boom") as err:
        arm.command(np.eye(4), 0.05)
    assert isinstance(err.value.__cause__, RuntimeError)
    assert len(ur.times("servoStop")) == 1  # the thread still tried to stop the arm


# ---------------------------------------------------------------------------- frames
def test_table_target_reaches_servol_as_the_base_frame_axis_angle_pose(ur, arms):
    base_from_table = [0.3, -0.2, 0.1, 0.1, -0.2, 0.7]
    B = _mat(base_from_table)
    T_table = _mat([0.40, 0.05, 0.20, 2.5, -1.6, 0.3])
    ur.actual = B @ _mat([0.41, 0.06, 0.21, 2.5, -1.6, 0.25])  # start 2 cm and 0.05 rad away
    hz = 125.0
    arm = connected(arms, ur, servo_hz=hz, base_from_table=base_from_table)
    assert ur.args("setTcp") == [([0.0, 0.0, 0.235, 0.0, 0.0, 0.0],)]
    stream(arm, T_table, 0.5)
    pose, speed, accel, t, lookahead, gain = ur.args("servoL")[-1]
    R_base = B[:3, :3] @ T_table[:3, :3]
    expected = [*(B[:3, :3] @ T_table[:3, 3] + B[:3, 3]), *Rotation.from_matrix(R_base).as_rotvec()]
    assert np.abs(np.array(pose) - expected).max() < 1e-9
    assert (speed, accel, t, lookahead, gain) == (0.0, 0.0, 1 / hz, 0.1, 300.0)
    arm.stop()  # the simulated TCP stops following: compare the measured pose at rest
    measured = np.linalg.inv(B) @ ur.actual
    assert np.abs(arm.tcp_pose() - measured).max() < 1e-9


def test_pose6_round_trip():
    pose6 = [0.1, -0.2, 0.3, 0.4, -1.1, 2.0]
    assert np.abs(pose6_to_mat(pose6) - _mat(pose6)).max() < 1e-12
    assert np.abs(np.array(mat_to_pose6(_mat(pose6))) - pose6).max() < 1e-12


# ---------------------------------------------------------------------------- settings and factories
@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("servo_hz", 1000.0),
        ("lookahead_time", 0.5),
        ("gain", 50.0),
        ("action_timeout_s", 0.0),
        ("max_pos_speed", float("nan")),
        ("base_from_table", [0.0] * 5),
        ("tcp_offset", [0, 0, float("inf"), 0, 0, 0]),
    ],
)
def test_settings_name_the_bad_field(field, value):
    with pytest.raises(ValueError, match=f"RtdeSettings.{field}="):
        RtdeSettings(host="h", **{field: value})


def test_missing_ur_rtde_names_the_extra(monkeypatch):
    for module in ("rtde_control", "rtde_receive", "dashboard_client"):
        monkeypatch.setitem(sys.modules, module, None)  # import now fails as if not installed
    for factory in (
        lambda: default_control_factory("h", 125.0),
        lambda: default_receive_factory("h", 125.0),
        lambda: default_dashboard_factory("h"),
    ):
        with pytest.raises(ImportError, match=r'pip install "lerobot_policy_bboxpick\[ur5\]"'):
            factory()
    assert INSTALL_HINT == 'pip install "lerobot_policy_bboxpick[ur5]"'


def test_make_rtde_arm_from_the_robot_config():
    from lerobot.cameras.opencv import OpenCVCameraConfig

    from lerobot_bboxpick.robots.ur5.configuration_ur5 import UR5Config

    config = UR5Config(
        backend="rtde",
        host="10.0.0.7",
        servo_rate_hz=125.0,
        bbox="0.4,0.5,0.5,0.6",
        base_from_table=[0.1, 0.2, 0.0, 0.0, 0.0, 1.0],
        tcp_offset_m=0.2,
        cameras={"wrist": OpenCVCameraConfig(index_or_path=0, width=1920, height=1080, fps=30)},
    )
    arm = make_rtde_arm(config)
    s = arm.settings
    assert (s.host, s.servo_hz, s.command_period_s, s.action_timeout_s) == ("10.0.0.7", 125.0, 0.05, 0.5)
    assert list(s.tcp_offset) == [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]
    assert list(s.base_from_table) == [0.1, 0.2, 0.0, 0.0, 0.0, 1.0]
    assert (s.max_pos_speed, s.max_rot_speed) == (
        config.safety.max_tcp_speed,
        config.safety.max_tcp_angular_speed,
    )
    assert arm.gripper.host == "10.0.0.7" and arm.gripper.port == 63352
