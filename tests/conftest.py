"""Shared fixtures: real MuJoCo envs rendered headless with EGL (no mocks)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from lerobot_bboxpick.sim.env import LegoPickEnv  # noqa: E402


@pytest.fixture(scope="module")
def grid_env():
    """A grid_id env that keeps running after a lift (for scripted situations)."""
    env = LegoPickEnv(setting="grid_id", terminate_on_lift=False)
    yield env
    env.close()
