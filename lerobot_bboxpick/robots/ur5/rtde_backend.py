"""``--robot.backend=rtde``: a real UR5 (CB3) / UR5e through ``ur_rtde``, servoing like UMI.

Behaviour follows UMI's ``rtde_interpolation_controller.py``: a control thread at the arm's servo rate
(125 Hz CB3, 500 Hz e-series) interpolates between the 20 Hz TCP targets given to :meth:`RtdeArm.command`
and sends ``servoL(pose, 0, 0, dt, lookahead_time, gain)`` every tick inside ``initPeriod()`` /
``waitPeriod()``. Each target is due ``command_period_s + action_latency_s`` after it arrives; the path
to it is linear in position and slerp in rotation, stretched so it never exceeds the speed bounds,
and a new target replaces whatever the schedule held beyond its due time (so a late target simply
becomes the next segment from where the arm is commanded now). Every pose sent also moves at most
``max_pos_speed * dt`` / ``max_rot_speed * dt`` from the previous one, so a stalled tick never makes
the arm jump.

Frames: targets and :meth:`RtdeArm.tcp_pose` are in the table frame (the datasets'); the arm works in
its base frame, ``T_base = base_from_table @ T_table``. The TCP is set with ``setTcp`` (UMI's fingertips:
0.235 m along the flange z axis).

Safety: ``setWatchdog`` + ``kickWatchdog`` every tick, so the controller's script stops the arm if this
process dies; no ``command`` for ``action_timeout_s`` makes the thread ``servoStop`` and hold until the
next command; a protective or emergency stop (read every tick) ends the servoing, and ``tcp_pose`` /
``command`` then raise :class:`ArmFault` naming the recovery (:meth:`RtdeArm.recover_protective_stop`).
An exception in the thread is never swallowed: it is raised as ``ArmFault`` by the next call.

``ur_rtde`` is an optional extra (``pip install "lerobot_policy_bboxpick[ur5]"``), imported only when a
real arm is connected; tests pass stand-in factories instead.
"""

from __future__ import annotations

import importlib
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import timedelta
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from lerobot_bboxpick import geometry
from lerobot_bboxpick.robots.ur5.backend import ArmBackend, ArmFault
from lerobot_bboxpick.robots.ur5.gripper import Gripper, Robotiq2F85
from lerobot_bboxpick.sim.controller import limit_step

if TYPE_CHECKING:
    from lerobot_bboxpick.robots.ur5.configuration_ur5 import UR5Config

log = logging.getLogger(__name__)

INSTALL_HINT = 'pip install "lerobot_policy_bboxpick[ur5]"'
PROTECTIVE_STOP_RECOVERY = (
    "clear the cause (move the arm away from the collision; the controller refuses to unlock during the "
    "first 5 s), then call RtdeArm.recover_protective_stop(), which runs DashboardClient.closeSafetyPopup() "
    "and unlockProtectiveStop(), then RTDEControlInterface.reuploadScript() (or reconnect) and resumes "
    "holding the current pose"
)
EMERGENCY_STOP_RECOVERY = (
    "release the emergency-stop button, close the safety pop-up, power on and release the brakes on the "
    "teach pendant (or DashboardClient.closeSafetyPopup(), powerOn(), brakeRelease()), then reconnect "
    "(disconnect() and connect())"
)

SERVOL_REFUSED = (
    "servoL was refused: the control script is not running (watchdog expired, stopped from the pendant, "
    "or a stop not yet reported); reconnect with disconnect() then connect()"
)


# ---------------------------------------------------------------------------- ur_rtde surface we use
class ControlInterface(Protocol):
    """The part of ``rtde_control.RTDEControlInterface`` (ur_rtde 1.6.5) this backend calls."""

    def servoL(  # noqa: N802 (ur_rtde's names)
        self,
        pose: list[float],
        speed: float,
        acceleration: float,
        time: float,
        lookahead_time: float,
        gain: float,
    ) -> bool: ...
    def servoStop(self, a: float = 10.0) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def initPeriod(self) -> Any: ...  # noqa: N802 (ur_rtde's names)
    def waitPeriod(self, t_cycle_start: Any) -> None: ...  # noqa: N802 (ur_rtde's names)
    def setTcp(self, tcp_offset: list[float]) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def setWatchdog(self, min_frequency: float = 10.0) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def kickWatchdog(self) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def stopScript(self) -> None: ...  # noqa: N802 (ur_rtde's names)
    def reuploadScript(self) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def isConnected(self) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def reconnect(self) -> bool: ...
    def disconnect(self) -> None: ...


class ReceiveInterface(Protocol):
    """The part of ``rtde_receive.RTDEReceiveInterface`` this backend calls."""

    def getActualTCPPose(self) -> list[float]: ...  # noqa: N802 (ur_rtde's names)
    def isProtectiveStopped(self) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def isEmergencyStopped(self) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def isConnected(self) -> bool: ...  # noqa: N802 (ur_rtde's names)
    def disconnect(self) -> None: ...


class DashboardInterface(Protocol):
    """The part of ``dashboard_client.DashboardClient`` this backend calls."""

    def connect(self, timeout_ms: int = 2000) -> None: ...
    def closeSafetyPopup(self) -> None: ...  # noqa: N802 (ur_rtde's names)
    def unlockProtectiveStop(self) -> None: ...  # noqa: N802 (ur_rtde's names)
    def disconnect(self) -> None: ...


ControlFactory = Callable[[str, float], ControlInterface]
ReceiveFactory = Callable[[str, float], ReceiveInterface]
DashboardFactory = Callable[[str], DashboardInterface]


def _import_ur_rtde(module: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise ImportError(
            f"the rtde backend needs ur_rtde (module {module!r} is missing): {INSTALL_HINT}"
        ) from e


def default_control_factory(host: str, frequency: float) -> ControlInterface:
    """``RTDEControlInterface(host, frequency)``: connects and uploads the control script."""
    return _import_ur_rtde("rtde_control").RTDEControlInterface(host, frequency)


def default_receive_factory(host: str, frequency: float) -> ReceiveInterface:
    """``RTDEReceiveInterface(host, frequency)``."""
    return _import_ur_rtde("rtde_receive").RTDEReceiveInterface(host, frequency)


def default_dashboard_factory(host: str) -> DashboardInterface:
    """``DashboardClient(host)`` (port 29999), not yet connected."""
    return _import_ur_rtde("dashboard_client").DashboardClient(host)


# ---------------------------------------------------------------------------- settings
@dataclass
class RtdeSettings:
    """Options of :class:`RtdeArm` (metres, radians, seconds, Hz)."""

    host: str
    # 125 on CB3 (UR5), 500 on e-series (UR5e): the servoL rate and the RTDE frequency.
    servo_hz: float = 500.0
    lookahead_time: float = 0.1  # servoL smoothing, ur_rtde allows 0.03..0.2
    gain: float = 300.0  # servoL proportional gain, ur_rtde allows 100..2000
    # A target is due command_period_s (the 20 Hz command period) + action_latency_s after it arrives.
    # action_latency_s is a buffer against late command() calls; the arm's own lag is compensated
    # upstream (the policy drops stale chunk steps: lerobot_bboxpick.latency), not here.
    command_period_s: float = 0.05
    action_latency_s: float = 0.0
    action_timeout_s: float = 0.5  # no command for this long: servoStop and hold
    max_pos_speed: float = 0.5  # m/s, bound of the interpolated TCP path
    max_rot_speed: float = 1.5  # rad/s
    stop_deceleration: float = 10.0  # m/s^2, servoStop(a); ur_rtde's default
    watchdog_min_hz: float = 10.0  # the script stops the arm when not kicked this often
    # Table frame in the base frame: x, y, z (m) and a rotation vector (rad).
    base_from_table: Sequence[float] = field(default_factory=lambda: [0.0] * 6)
    # setTcp: flange -> TCP as x, y, z (m) and a rotation vector (rad); UMI's fingertips by default.
    tcp_offset: Sequence[float] = field(default_factory=lambda: [0.0, 0.0, 0.235, 0.0, 0.0, 0.0])
    recovery_timeout_s: float = 3.0  # wait for the protective stop to clear after unlocking

    def __post_init__(self) -> None:
        checks = (
            ("servo_hz", 0 < self.servo_hz <= 500, "in (0, 500] (125 on CB3, 500 on e-series)"),
            ("lookahead_time", 0.03 <= self.lookahead_time <= 0.2, "in [0.03, 0.2] s"),
            ("gain", 100 <= self.gain <= 2000, "in [100, 2000]"),
            ("command_period_s", self.command_period_s > 0, "> 0 s"),
            ("action_latency_s", self.action_latency_s >= 0, ">= 0 s"),
            ("action_timeout_s", self.action_timeout_s > 0, "> 0 s"),
            ("max_pos_speed", self.max_pos_speed > 0, "> 0 m/s"),
            ("max_rot_speed", self.max_rot_speed > 0, "> 0 rad/s"),
            ("stop_deceleration", self.stop_deceleration > 0, "> 0 m/s^2"),
            ("watchdog_min_hz", self.watchdog_min_hz > 0, "> 0 Hz"),
            ("recovery_timeout_s", self.recovery_timeout_s > 0, "> 0 s"),
        )
        for name, ok, allowed in checks:
            value = getattr(self, name)
            if not (math.isfinite(value) and ok):
                raise ValueError(f"RtdeSettings.{name}={value!r} must be {allowed}")
        for name in ("base_from_table", "tcp_offset"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (6,) or not np.all(np.isfinite(value)):
                raise ValueError(
                    f"RtdeSettings.{name}={list(getattr(self, name))} must be 6 finite numbers: "
                    "x, y, z (m) and a rotation vector (rad)"
                )

    @property
    def schedule_delay_s(self) -> float:
        """How long after it arrives a target is due."""
        return self.command_period_s + self.action_latency_s


def pose6_to_mat(pose6: Sequence[float]) -> np.ndarray:
    """UR pose (x, y, z, rotation vector) -> 4x4, through :mod:`lerobot_bboxpick.geometry`."""
    p = np.asarray(pose6, dtype=np.float64)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = geometry.axis_angle_to_mat(p[3:]), p[:3]
    return T


def mat_to_pose6(T: np.ndarray) -> list[float]:
    """4x4 -> UR pose (x, y, z, rotation vector) as the list ``ur_rtde`` takes."""
    return [*map(float, T[:3, 3]), *map(float, geometry.mat_to_axis_angle(T[:3, :3]))]


# ---------------------------------------------------------------------------- interpolation
class PoseSchedule:
    """Timed TCP waypoints; linear in position and slerp in rotation between them, held past the ends."""

    def __init__(self, t: float, T: np.ndarray) -> None:
        self.times: list[float] = [t]
        self.poses: list[np.ndarray] = [np.array(T, dtype=np.float64)]
        self._rotvec_cache: tuple[int, np.ndarray | None] = (-1, None)  # (segment, its rotation vector)

    def at(self, t: float) -> np.ndarray:
        """The pose at time ``t``."""
        if t <= self.times[0]:
            return self.poses[0].copy()
        if t >= self.times[-1]:
            return self.poses[-1].copy()
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        t0, t1 = self.times[i], self.times[i + 1]
        alpha = (t - t0) / (t1 - t0)
        A, B = self.poses[i], self.poses[i + 1]
        if self._rotvec_cache[0] != i:  # one log map per segment, not per tick
            self._rotvec_cache = (i, geometry.mat_to_axis_angle(A[:3, :3].T @ B[:3, :3]))
        T = np.eye(4)
        T[:3, 3] = A[:3, 3] + alpha * (B[:3, 3] - A[:3, 3])
        T[:3, :3] = A[:3, :3] @ geometry.axis_angle_to_mat(alpha * self._rotvec_cache[1])
        return T

    def insert(
        self, now: float, due: float, T: np.ndarray, max_pos_speed: float, max_rot_speed: float
    ) -> float:
        """Make ``T`` due at ``due`` (later if the speed bounds need it); returns the time it got.

        The schedule restarts at ``now`` from its own pose there; waypoints after ``due`` are replaced.
        """
        start = self.at(now)
        kept = [(t, P) for t, P in zip(self.times, self.poses, strict=True) if now < t < due]
        times, poses = [now] + [t for t, _ in kept], [start] + [P for _, P in kept]
        last = poses[-1]
        distance = float(np.linalg.norm(T[:3, 3] - last[:3, 3]))
        angle = float(np.linalg.norm(geometry.mat_to_axis_angle(last[:3, :3].T @ T[:3, :3])))
        due = max(due, times[-1] + max(distance / max_pos_speed, angle / max_rot_speed))
        if due <= times[-1]:  # a zero-length move due now: hold it from now on
            times, poses = [now], [start]
            due = now + 1e-9
        self.times, self.poses = times + [due], poses + [np.array(T, dtype=np.float64)]
        self._rotvec_cache = (-1, None)
        return due


# ---------------------------------------------------------------------------- the backend
class RtdeArm(ArmBackend):
    """A UR arm through ``ur_rtde`` plus a :class:`Gripper`; see the module docstring."""

    def __init__(
        self,
        settings: RtdeSettings,
        gripper: Gripper,
        control_factory: ControlFactory = default_control_factory,
        receive_factory: ReceiveFactory = default_receive_factory,
        dashboard_factory: DashboardFactory = default_dashboard_factory,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.settings = settings
        self.gripper = gripper
        self._control_factory, self._receive_factory = control_factory, receive_factory
        self._dashboard_factory = dashboard_factory
        self._clock = clock
        self._base_from_table = pose6_to_mat(settings.base_from_table)
        self._table_from_base = np.linalg.inv(self._base_from_table)
        self._control: ControlInterface | None = None
        self._receive: ReceiveInterface | None = None
        self._thread: threading.Thread | None = None
        self._quit = threading.Event()
        self._lock = threading.Lock()  # guards everything below, shared with the thread
        self._inbox: list[tuple[float, np.ndarray]] = []  # (arrival time, base-frame target)
        self._last_command_time: float | None = None
        self._stop_requested = False
        self._stopped = threading.Event()  # set while the thread holds without servoing
        self._measured: np.ndarray | None = None  # base-frame TCP pose of the last tick
        self._fault: ArmFault | None = None
        self._fault_kind: str | None = None  # "protective", "emergency", "error"
        self._connected = False

    @property
    def schedule_delay_s(self) -> float:
        """How long after ``command`` a target is due (``latency.command_send_time`` uses it)."""
        return self.settings.schedule_delay_s

    @property
    def is_connected(self) -> bool:
        """Whether ``connect`` succeeded and ``disconnect`` was not called since."""
        return self._connected

    # ------------------------------------------------------------------ ArmBackend
    def connect(self) -> None:
        """Connect RTDE control + receive and the gripper, set the TCP and watchdog, hold the current pose."""
        if self._connected:
            raise RuntimeError("RtdeArm is already connected (call disconnect() first)")
        s = self.settings
        with self._lock:
            self._fault = self._fault_kind = None
        self._control = self._control_factory(s.host, s.servo_hz)
        try:
            self._receive = self._receive_factory(s.host, s.servo_hz)
            if self._check_safety():
                raise self._fault  # type: ignore[misc]
            self._configure_script()
            self.gripper.connect()
        except BaseException:
            self._shutdown_interfaces()
            raise
        self._connected = True
        self._start_thread()

    def disconnect(self) -> None:
        """Stop the thread, then ``servoStop``, ``stopScript``, disconnect control and receive, and the
        gripper; every step is attempted (failures are logged); safe to call twice."""
        if not self._connected:
            return
        self._connected = False
        self._join_thread()
        self._shutdown_interfaces()

    def tcp_pose(self) -> np.ndarray:
        """The TCP pose measured at the last tick (4x4, table frame); raises ``ArmFault`` after a stop."""
        self._raise_fault()
        with self._lock:
            measured = self._measured
        if measured is None:
            raise RuntimeError("RtdeArm is not connected: call connect() first")
        return self._table_from_base @ measured

    def gripper_width(self) -> float:
        """The gripper's measured width (m)."""
        return self.gripper.width()

    def command(self, T: np.ndarray, width: float) -> None:
        """Schedule TCP pose ``T`` (table frame) ``schedule_delay_s`` from now and move the gripper."""
        self._raise_fault()
        if not self._connected:
            raise RuntimeError("RtdeArm is not connected: call connect() first")
        T_base = self._base_from_table @ np.asarray(T, dtype=np.float64)
        with self._lock:
            now = self._clock()
            self._inbox.append((now, T_base))
            self._last_command_time = now
            self._stop_requested = False
        self.gripper.set_width(width)

    def stop(self) -> None:
        """``servoStop`` now and hold (the thread still kicks the watchdog); the next ``command`` resumes."""
        if not (self._connected and self._thread is not None and self._thread.is_alive()):
            return
        with self._lock:
            self._stop_requested = True
            self._inbox.clear()
        # Wait (bounded) for the thread to have stopped, so no servoL follows this call.
        self._stopped.wait(timeout=max(0.5, 20.0 / self.settings.servo_hz))

    # ------------------------------------------------------------------ recovery
    def recover_protective_stop(self) -> None:
        """After a protective stop whose cause is cleared: ``closeSafetyPopup`` and ``unlockProtectiveStop``
        through a ``DashboardClient``, then ``reuploadScript`` (``reconnect`` if the link dropped), set the
        TCP and watchdog again, and resume holding the current pose. Raises ``ArmFault`` if it cannot."""
        if not self._connected or self._control is None or self._receive is None:
            raise RuntimeError("RtdeArm is not connected: call connect() first")
        with self._lock:
            kind, fault = self._fault_kind, self._fault
        if kind == "emergency" or self._receive.isEmergencyStopped():
            raise ArmFault(
                f"the arm is emergency-stopped, which software cannot clear: {EMERGENCY_STOP_RECOVERY}"
            )
        if kind not in (None, "protective") and not self._receive.isProtectiveStopped():
            raise ArmFault(f"not a protective stop ({fault}): reconnect with disconnect() then connect()")
        self._join_thread()
        dashboard = self._dashboard_factory(self.settings.host)
        dashboard.connect()
        try:
            dashboard.closeSafetyPopup()
            dashboard.unlockProtectiveStop()
        finally:
            dashboard.disconnect()
        deadline = self._clock() + self.settings.recovery_timeout_s
        while self._receive.isProtectiveStopped():
            if self._clock() > deadline:
                raise ArmFault(
                    "the arm is still protective-stopped after unlockProtectiveStop (the controller refuses "
                    f"during the first 5 s after the stop, or the cause persists): {PROTECTIVE_STOP_RECOVERY}"
                )
            time.sleep(0.05)
        if self._control.isConnected():
            if not self._control.reuploadScript():
                raise ArmFault(
                    "reuploadScript() failed after the protective stop: reconnect (disconnect(), connect())"
                )
        elif not self._control.reconnect():
            raise ArmFault(
                "RTDE control reconnect() failed after the protective stop: check the network link"
            )
        self._configure_script()
        with self._lock:
            self._fault = self._fault_kind = None
        self._start_thread()
        log.info("protective stop cleared; holding the current pose")

    # ------------------------------------------------------------------ internals
    def _configure_script(self) -> None:
        c = self._control
        assert c is not None
        s = self.settings
        if c.setTcp(list(map(float, s.tcp_offset))) is False:
            raise ArmFault(f"setTcp({list(s.tcp_offset)}) was refused by the controller")
        if c.setWatchdog(s.watchdog_min_hz) is False:
            raise ArmFault(f"setWatchdog({s.watchdog_min_hz}) was refused by the controller")

    def _check_safety(self) -> bool:
        """Read the stop flags; on a stop, record the fault and return True."""
        r = self._receive
        assert r is not None
        if r.isEmergencyStopped():
            self._set_fault("emergency", ArmFault(f"the arm is emergency-stopped: {EMERGENCY_STOP_RECOVERY}"))
            return True
        if r.isProtectiveStopped():
            self._set_fault(
                "protective", ArmFault(f"the arm is in a protective stop: {PROTECTIVE_STOP_RECOVERY}")
            )
            return True
        return False

    def _set_fault(self, kind: str, fault: ArmFault) -> None:
        with self._lock:
            if self._fault is None:
                self._fault, self._fault_kind = fault, kind
        log.error("%s", fault)

    def _raise_fault(self) -> None:
        with self._lock:
            fault = self._fault
        if fault is not None:
            raise fault

    def _start_thread(self) -> None:
        r = self._receive
        assert r is not None
        with self._lock:
            self._measured = pose6_to_mat(r.getActualTCPPose())
            self._inbox.clear()
            self._last_command_time = None
            self._stop_requested = False
        self._quit.clear()
        self._thread = threading.Thread(target=self._run, name="rtde-servo", daemon=True)
        self._thread.start()

    def _join_thread(self) -> None:
        self._quit.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            if self._thread.is_alive():
                log.error("the RTDE control thread did not stop within 2 s")
            self._thread = None

    def _shutdown_interfaces(self) -> None:
        c, r = self._control, self._receive
        steps: list[tuple[str, Callable[[], object]]] = []
        if c is not None:
            steps += [
                ("servoStop", lambda: c.servoStop(self.settings.stop_deceleration)),
                ("stopScript", c.stopScript),
                ("RTDEControlInterface.disconnect", c.disconnect),
            ]
        if r is not None:
            steps.append(("RTDEReceiveInterface.disconnect", r.disconnect))
        steps.append(("gripper.disconnect", self.gripper.disconnect))
        for name, step in steps:
            try:
                step()
            except Exception as e:  # keep going: every later step must still run
                log.warning("RtdeArm shutdown: %s failed: %r", name, e)
        self._control = self._receive = None
        with self._lock:
            self._measured = None

    def _run(self) -> None:
        c, r, s = self._control, self._receive, self.settings
        assert c is not None and r is not None
        dt = 1.0 / s.servo_hz
        max_step, max_turn = s.max_pos_speed * dt, s.max_rot_speed * dt
        # initPeriod() returns ur_rtde's steady-clock time point as a timedelta; waitPeriod takes one.
        period, max_lag = timedelta(seconds=dt), 5 * dt
        t_grid: timedelta | None = None
        holding = True  # not servoing: at connect, after a stop or an action timeout
        self._stopped.set()
        schedule: PoseSchedule | None = None
        T_sent: np.ndarray | None = None
        try:
            while not self._quit.is_set():
                t_cycle = c.initPeriod()
                # Ticks on a fixed grid (as UMI's loop): a late tick shortens the next waits so the rate
                # holds; after a stall of several ticks the grid restarts instead of bursting servoL.
                if t_grid is None or (t_cycle - t_grid).total_seconds() > max_lag:
                    t_grid = t_cycle
                if self._check_safety():
                    return  # the controller stopped the arm itself: no servoStop, no more servoL
                T_meas = pose6_to_mat(r.getActualTCPPose())
                now = self._clock()
                with self._lock:
                    self._measured = T_meas
                    inbox, self._inbox = self._inbox, []
                    last_command, stop_requested = self._last_command_time, self._stop_requested
                if stop_requested and not holding:
                    c.servoStop(s.stop_deceleration)
                    holding, schedule = True, None
                    self._stopped.set()
                elif not holding and last_command is not None and now - last_command > s.action_timeout_s:
                    c.servoStop(s.stop_deceleration)
                    holding, schedule = True, None
                    self._stopped.set()
                    log.warning(
                        "no command for %.3f s (action_timeout_s=%.3f): arm stopped, holding until the next",
                        now - last_command,
                        s.action_timeout_s,
                    )
                if inbox and not stop_requested:
                    if holding:  # resume from where the arm is, not from the last pose sent
                        schedule, T_sent, holding = PoseSchedule(now, T_meas), T_meas, False
                        self._stopped.clear()
                    assert schedule is not None
                    for arrival, T_target in inbox:
                        schedule.insert(
                            now, arrival + s.schedule_delay_s, T_target, s.max_pos_speed, s.max_rot_speed
                        )
                if not holding:
                    assert schedule is not None and T_sent is not None
                    T_cmd, _ = limit_step(T_sent, schedule.at(now), max_step, max_turn)
                    if not c.servoL(mat_to_pose6(T_cmd), 0.0, 0.0, dt, s.lookahead_time, s.gain):
                        if not self._check_safety():
                            self._set_fault("error", ArmFault(SERVOL_REFUSED))
                        return
                    T_sent = T_cmd
                c.kickWatchdog()
                c.waitPeriod(t_grid)  # returns at t_grid + dt (at once if that has passed)
                t_grid += period
        except Exception as e:
            fault = ArmFault(
                f"the RTDE control thread failed: {e!r}; reconnect with disconnect() then connect()"
            )
            fault.__cause__ = e
            log.exception("RTDE control thread failed")
            self._set_fault("error", fault)
            try:
                c.servoStop(s.stop_deceleration)
            except Exception as stop_error:
                log.warning("servoStop after the thread failure failed too: %r", stop_error)
        finally:
            self._stopped.set()


# ---------------------------------------------------------------------------- from the robot config
def make_rtde_arm(config: UR5Config) -> RtdeArm:
    """An :class:`RtdeArm` with a Robotiq 2F-85 from the ``ur5`` robot's options (``--robot.*``)."""
    if config.gripper != "robotiq_2f85":
        raise ValueError(f"robot.gripper={config.gripper!r} is not one of: robotiq_2f85")
    settings = RtdeSettings(
        host=config.host,
        servo_hz=float(config.servo_rate_hz),
        lookahead_time=float(config.lookahead_time),
        gain=float(config.gain),
        command_period_s=1.0 / config.fps,
        action_timeout_s=float(config.action_timeout_s),
        max_pos_speed=float(config.safety.max_tcp_speed),
        max_rot_speed=float(config.safety.max_tcp_angular_speed),
        base_from_table=list(config.base_from_table),
        tcp_offset=[0.0, 0.0, float(config.tcp_offset_m), 0.0, 0.0, 0.0],
    )
    return RtdeArm(settings, Robotiq2F85(config.host))
