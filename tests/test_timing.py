"""UMI-style latency compensation (lerobot_bboxpick.robots.ur5.timing), with numbers."""

from __future__ import annotations

import numpy as np
import pytest

from lerobot_bboxpick.robots.ur5.timing import (
    GOPRO_ELGATO_CAMERA_LATENCY_S,
    UR_ACTION_LATENCY_S,
    command_send_time,
    observation_time,
    schedule_chunk,
)


def chunk(n: int = 16) -> np.ndarray:
    a = np.zeros((n, 10))
    a[:, 0] = np.arange(n)  # step index in x, to identify the steps kept
    return a


def test_observation_time_subtracts_the_camera_latency():
    assert GOPRO_ELGATO_CAMERA_LATENCY_S == 0.17
    assert observation_time(100.0) == pytest.approx(99.83)
    assert observation_time(100.0, camera_latency_s=0.125) == pytest.approx(99.875)
    with pytest.raises(ValueError, match="camera_latency_s"):
        observation_time(100.0, camera_latency_s=-0.1)


def test_schedule_drops_the_steps_whose_time_has_passed():
    # Observation captured at 10.00 s (received 10.17 s), inference done at 10.31 s, 20 Hz chunk.
    pairs = schedule_chunk(chunk(), obs_time=10.0, dt=0.05, now=10.31, action_latency_s=0.1)
    # Step i is commanded for 10.0 + 0.05 i - 0.1; only i with 9.9 + 0.05 i > 10.31, i.e. i >= 9, remain.
    assert [int(a[0]) for a, _ in pairs] == list(range(9, 16))
    assert [t for _, t in pairs] == pytest.approx([9.9 + 0.05 * i for i in range(9, 16)])
    assert UR_ACTION_LATENCY_S == 0.1


def test_a_step_due_exactly_now_is_dropped_and_zero_latency_keeps_more():
    pairs = schedule_chunk(chunk(4), obs_time=0.0, dt=0.25, now=0.5, action_latency_s=0.0)
    assert [int(a[0]) for a, _ in pairs] == [3]  # step 2 is due at exactly 0.5: passed
    pairs = schedule_chunk(chunk(4), obs_time=0.0, dt=0.25, now=0.49, action_latency_s=0.0)
    assert [t for _, t in pairs] == pytest.approx([0.5, 0.75])


def test_all_late_holds_the_last_action_on_the_next_grid_step():
    # Chunk of 16 at 20 Hz from obs 10.0 ends at 10.65 (- 0.1 latency = 10.55); inference finished at 11.02.
    pairs = schedule_chunk(chunk(), obs_time=10.0, dt=0.05, now=11.02, action_latency_s=0.1)
    assert len(pairs) == 1
    action, t = pairs[0]
    assert int(action[0]) == 15
    assert t == pytest.approx(11.05)  # 9.9 + 23 * 0.05: the first grid time after 11.02
    assert schedule_chunk(chunk(), 10.0, 0.05, 11.02, 0.1, hold_last_if_late=False) == []
    # On a grid point exactly: the next one.
    assert schedule_chunk(chunk(2), 0.0, 0.5, 2.0, 0.0)[0][1] == pytest.approx(2.5)


def test_the_chunk_is_copied_not_aliased():
    a = chunk(3)
    pairs = schedule_chunk(a, 0.0, 0.1, -1.0, 0.0)
    pairs[0][0][0] = 99.0
    assert a[0, 0] == 0.0


def test_command_send_time():
    # RtdeArm schedules a target 0.05 s (its command period) after it arrives.
    assert command_send_time(10.35, 0.05) == pytest.approx(10.30)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"actions": np.zeros((16, 9))}, r"shape \(N, 10\)"),
        ({"actions": np.zeros(10)}, r"shape \(N, 10\)"),
        ({"dt": 0.0}, "dt"),
        ({"now": float("nan")}, "now"),
        ({"action_latency_s": -0.01}, "action_latency_s"),
        ({"obs_time": float("inf")}, "obs_time"),
    ],
)
def test_bad_arguments_name_the_field(kwargs, match):
    args = {"actions": chunk(), "obs_time": 0.0, "dt": 0.05, "now": 0.0, "action_latency_s": 0.1} | kwargs
    with pytest.raises(ValueError, match=match):
        schedule_chunk(**args)
