"""UMI-style latency compensation (lerobot_bboxpick.latency), with numbers."""

from __future__ import annotations

import numpy as np
import pytest

from lerobot_bboxpick.latency import (
    GOPRO_ELGATO_CAMERA_LATENCY_S,
    UR_ACTION_LATENCY_S,
    command_send_time,
    fresh_steps,
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


def test_fresh_steps_names_its_own_bad_start_time():
    with pytest.raises(ValueError, match="start_time"):
        fresh_steps(16, float("nan"), 0.05, 0.0)
    assert fresh_steps(4, 0.0, 0.25, 0.5, 0.0).tolist() == [3]


# ---------------------------------------------------------------- on the action path (bbox_diffusion)


class FakeClock:
    """Returns the given times in order: select_action reads the clock on entry and when a chunk is ready."""

    def __init__(self, *times: float) -> None:
        self.times = list(times)

    def __call__(self) -> float:
        return self.times.pop(0)


def _latency_policy(**overrides):
    from test_rl_modeling import tiny_policy

    return tiny_policy(**overrides).eval()


def _one_obs():
    from test_rl_modeling import obs

    return {k: v[:, -1] for k, v in obs(1).items()}  # one observation, as a robot gives it


def test_the_policy_drops_the_chunk_steps_already_due_and_keeps_the_rest():
    import torch

    policy = _latency_policy(compensate_latency=True, camera_latency_s=0.17, action_latency_s=0.1)
    batch = _one_obs()
    expected = policy.predict_action_chunk(
        {k: v[:, None].repeat(1, 2, *([1] * (v.ndim - 1))) for k, v in batch.items()},
        generator=torch.Generator().manual_seed(3),
    )[0]
    # Received at 0.0 (captured -0.17), chunk ready at 0.2: step i is due at -0.17 + 0.05 (i + 1) and
    # commanded 0.1 s earlier, at -0.22 + 0.05 i, so steps with that <= 0.2, i.e. i <= 8, are dropped.
    policy.clock = FakeClock(0.0, 0.2, *[1.0] * 7)
    policy.reset()
    executed = [policy.select_action(batch, generator=torch.Generator().manual_seed(3))[0]]
    executed += [policy.select_action(batch)[0] for _ in range(6)]
    assert torch.allclose(torch.stack(executed), expected[9:16], atol=1e-5)
    assert len(policy._actions) == 0  # 7 fresh steps (< n_action_steps=12): the next call predicts again
    # A chunk ready at once: the two latencies alone (0.27 s) make steps 0-4 due; 11 remain, all queued.
    policy.clock = FakeClock(5.0, 5.0)
    policy.select_action(batch)
    assert len(policy._actions) == 10


def test_without_compensation_every_step_is_executed_and_the_clock_ignored():
    import torch

    policy = _latency_policy()
    assert policy.config.compensate_latency is False
    batch = _one_obs()
    expected = policy.predict_action_chunk(
        {k: v[:, None].repeat(1, 2, *([1] * (v.ndim - 1))) for k, v in batch.items()},
        generator=torch.Generator().manual_seed(3),
    )[0]
    policy.clock = FakeClock(*[0.0] * 12)
    policy.reset()
    executed = [policy.select_action(batch, generator=torch.Generator().manual_seed(3))[0]]
    executed += [policy.select_action(batch)[0] for _ in range(11)]
    assert torch.allclose(torch.stack(executed), expected[:12], atol=1e-5)


def test_a_chunk_later_than_its_horizon_holds_its_last_step():
    import torch

    policy = _latency_policy(compensate_latency=True, camera_latency_s=0.0, action_latency_s=0.0)
    batch = _one_obs()
    policy.clock = FakeClock(0.0, 2.0)  # 16 steps at 20 Hz end at 0.8 s: all late
    policy.reset()
    policy.select_action(batch, generator=torch.Generator().manual_seed(3))
    assert len(policy._actions) == 0  # the last step alone was executed; the next call predicts again


@pytest.mark.parametrize(
    ("field", "value"), [("camera_latency_s", -0.1), ("action_latency_s", float("nan")), ("control_fps", 0.0)]
)
def test_bad_latency_settings_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        _latency_policy(**{field: value})


def test_lerobot_rollout_takes_the_latency_flags_with_a_checkpoint(tmp_path):
    """The flags a real-arm user passes to lerobot-rollout reach a checkpoint's config (LeRobot's parser)."""
    from lerobot.configs.policies import PreTrainedConfig

    _latency_policy().save_pretrained(tmp_path)
    config = PreTrainedConfig.from_pretrained(
        tmp_path, cli_overrides=["--compensate_latency=true", "--camera_latency_s=0.13"]
    )
    assert (config.compensate_latency, config.camera_latency_s, config.action_latency_s) == (True, 0.13, 0.1)
