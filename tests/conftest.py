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


@pytest.fixture(scope="module")
def reference():
    """The dashboard tests' scene (``helpers_dashboard``) in an env of its own: the numbers (boxes,
    pixels, poses) the dashboard's scene is checked against."""
    from helpers_dashboard import SEED, SETTING

    env = LegoPickEnv(setting=SETTING)
    env.reset(seed=SEED)
    yield env
    env.close()
