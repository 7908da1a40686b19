"""Benchmarks (figures, not pass/fail tests): env steps per second beside the bare render rate.

Both are measured in the same run, per setting, so the ratio says how much the env adds on top of
rendering the wrist view (physics substeps, IK, fisheye warp, bbox projection, outcome tracking).
"""

from __future__ import annotations

import time

import numpy as np

from lerobot_bboxpick.expert import ScriptedExpert
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.layouts import SETTINGS


def bench_env(setting: str, steps: int = 120, renders: int = 120, seed: int = 0) -> dict[str, float]:
    """Env steps/s (scripted-expert actions, so contacts and grasps happen) and bare render fps."""
    env = LegoPickEnv(setting=setting, terminate_on_lift=False)
    env.reset(seed=seed)
    expert = ScriptedExpert(np.random.default_rng(seed))
    expert.reset(env)
    actions = [expert.act() for _ in range(steps)]
    env.camera.render_pinhole(env.data)  # warm-up: first frame compiles shaders
    t0 = time.perf_counter()
    for _ in range(renders):
        env.camera.render_pinhole(env.data)
    render_fps = renders / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
    steps_per_s = steps / (time.perf_counter() - t0)
    env.close()
    return {
        "setting": setting,
        "env_steps_per_s": steps_per_s,
        "bare_render_fps": render_fps,
        "ratio": steps_per_s / render_fps,
    }


def bench_table(settings: tuple[str, ...] = SETTINGS, steps: int = 120) -> str:
    """Markdown table of ``bench_env`` for each setting."""
    lines = [
        "| setting | env steps/s | bare render fps (512 px wide view) | env / render |",
        "|---|---|---|---|",
    ]
    for s in settings:
        r = bench_env(s, steps=steps)
        lines.append(f"| {s} | {r['env_steps_per_s']:.1f} | {r['bare_render_fps']:.1f} | {r['ratio']:.2f} |")
    return "\n".join(lines)
