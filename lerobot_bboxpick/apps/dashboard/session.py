"""``DashboardSession``: the dashboard's state and commands, all simulation on one ``SimWorker`` thread.

Commands (load a scene, set the target, run, pause, resume, step, reset) are jobs on the worker;
a running rollout advances one tick (one control step of every lane) between jobs. What the page
shows is published as an immutable ``Snapshot`` (status + JPEG frames) that readers take without
waiting for the worker, so many browsers can watch while one drives.

Phases: ``empty`` (no scene) -> ``ready`` (scene and target set) -> ``running`` <-> ``paused`` ->
``done``; ``reset`` goes back to ``ready`` on the same scene and target, ``error`` is a run whose
policy raised (its message is in the status).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_bboxpick.apps.dashboard.boxes import brick_at, check_box, check_point, match_brick
from lerobot_bboxpick.apps.dashboard.errors import RequestError
from lerobot_bboxpick.apps.dashboard.lane import BBOX_MODES, Lane
from lerobot_bboxpick.apps.dashboard.policies import PolicyCatalog, PolicyChoice
from lerobot_bboxpick.apps.dashboard.views import ThirdPersonView, encode_jpeg, video_frame
from lerobot_bboxpick.apps.dashboard.worker import SimWorker
from lerobot_bboxpick.keys import ENV_BBOX, ENV_CAMERA, ENV_PIXELS
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.scene import N_BRICKS

SLOTS = ("A", "B")
MAX_SEED = 2**31 - 1
MAX_STEPS_LIMIT = 1000
DEFAULT_MAX_STEPS = 300  # the env's default episode length
EPISODE_FORMAT = "bboxpick-dashboard-episode/1"
CALL_TIMEOUT_S = 300.0  # a checkpoint load on a busy 2-core machine can take a while


@dataclass(frozen=True)
class Snapshot:
    """What the page shows at one moment: ``status`` (JSON-able) and JPEG ``frames`` by view name.

    Views: ``scene`` (the first wrist frame, the drawing surface), ``wrist_A``, ``third_A``,
    ``wrist_B``, ``third_B`` (the lanes' live views).
    """

    version: int
    status: dict
    frames: dict[str, bytes] = field(default_factory=dict)


@dataclass
class Scene:
    """A loaded scene: its first wrist frame, every brick's box and mask, and the chosen target."""

    setting: str
    seed: int
    image: np.ndarray
    brick_boxes: np.ndarray  # (N_BRICKS, 4) normalised, zeros when out of view
    masks: np.ndarray  # (H, W) brick index per pixel, -1 elsewhere
    colors: tuple[str, ...]
    target: int
    box: np.ndarray | None  # the box the policy will be given first (None: target out of view)
    target_source: str  # "seed", "box" or "click"
    target_iou: float | None  # IoU of the drawn box with the target's projected box
    version: int

    def as_json(self) -> dict:
        """The scene part of the status."""
        return {
            "setting": self.setting,
            "seed": self.seed,
            "target": self.target,
            "target_color": self.colors[self.target],
            "box": None if self.box is None else [float(v) for v in self.box],
            "target_box": [float(v) for v in self.brick_boxes[self.target]],
            "target_source": self.target_source,
            "target_iou": self.target_iou,
            "version": self.version,
            "image_size": [int(self.image.shape[1]), int(self.image.shape[0])],
        }


@dataclass
class Run:
    """The lanes of one run and how it is played."""

    lanes: list[Lane]
    realtime: bool
    max_steps: int
    bbox_mode: str
    period_s: float
    tick: int = 0
    due: float = 0.0
    started: float = field(default_factory=time.perf_counter)
    tick_times: list[float] = field(default_factory=list)

    @property
    def done(self) -> bool:
        """Every lane's episode has ended."""
        return all(lane.done for lane in self.lanes)


class DashboardSession:
    """The dashboard's library core: call its methods from any thread; MuJoCo runs on its worker."""

    def __init__(self, catalog: PolicyCatalog | None = None) -> None:
        self.catalog = catalog or PolicyCatalog()
        self._envs: list[Any] = []
        self._views: list[ThirdPersonView] = []
        self._env_setting: str | None = None
        self._scene: Scene | None = None
        self._run: Run | None = None
        self._phase = "empty"
        self._message = "load a scene"
        self._error: str | None = None
        self._scene_version = 0
        self._version = 0
        self._frames: dict[str, bytes] = {}
        self._snapshot = Snapshot(0, self._status())
        self._published = threading.Condition()
        self._worker = SimWorker(self._tick, self._tick_failed)

    # ------------------------------------------------------------------ reading (any thread, no wait)
    def snapshot(self) -> Snapshot:
        """The latest published snapshot."""
        return self._snapshot

    def wait_snapshot(self, after_version: int, timeout: float) -> Snapshot:
        """The first snapshot newer than ``after_version`` (or the current one after ``timeout`` s)."""
        with self._published:
            self._published.wait_for(lambda: self._snapshot.version > after_version, timeout=timeout)
            return self._snapshot

    def config(self) -> dict:
        """What the page offers: settings, policies, box modes, limits."""
        return {
            "mode": "sim",
            "settings": list(SETTINGS),
            "policies": [c.as_json() for c in self.catalog.choices()],
            "bbox_modes": list(BBOX_MODES),
            "max_steps_limit": MAX_STEPS_LIMIT,
            "default_max_steps": DEFAULT_MAX_STEPS,
            "n_bricks": N_BRICKS,
        }

    # ------------------------------------------------------------------ commands (queued on the worker)
    def load_scene(self, setting: str, seed: int) -> dict:
        """Load scene ``seed`` of ``setting``; the target is the seed's, its box the env's box of it."""
        if setting not in SETTINGS:
            raise RequestError(
                f"setting={setting!r} is not a lego_pick setting; valid settings: {', '.join(SETTINGS)}",
                field="setting",
            )
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
            raise RequestError(f"seed={seed!r} must be an integer in [0, {MAX_SEED}]", field="seed")
        return self._call(self._load_scene, setting, seed)

    def set_target(self, box: list[float] | None = None, point: list[float] | None = None) -> dict:
        """Designate the target by a drawn ``box`` (the brick it overlaps best) or a clicked ``point``."""
        if (box is None) == (point is None):
            raise RequestError("give exactly one of box (x0, y0, x1, y1) or point (x, y)", field="box")
        checked_box = None if box is None else check_box(box)
        checked_point = None if point is None else check_point(point)
        return self._call(self._set_target, checked_box, checked_point)

    def run(
        self,
        policies: list[str],
        bbox_mode: str = "tracked",
        realtime: bool = True,
        max_steps: int = DEFAULT_MAX_STEPS,
        start_paused: bool = False,
    ) -> dict:
        """Start one policy (or two side by side) on the scene and its box."""
        if not 1 <= len(policies) <= len(SLOTS):
            raise RequestError(
                f"policies must name 1 or 2 policies (2 = side by side), got {len(policies)}",
                field="policies",
            )
        if bbox_mode not in BBOX_MODES:
            raise RequestError(
                f"bbox_mode={bbox_mode!r} is not known; valid: {', '.join(BBOX_MODES)}", field="bbox_mode"
            )
        if (
            isinstance(max_steps, bool)
            or not isinstance(max_steps, int)
            or not 1 <= max_steps <= MAX_STEPS_LIMIT
        ):
            raise RequestError(
                f"max_steps={max_steps!r} must be an integer in [1, {MAX_STEPS_LIMIT}]", field="max_steps"
            )
        choices = [self.catalog.resolve(p, field=f"policies[{i}]") for i, p in enumerate(policies)]
        return self._call(self._start, choices, bbox_mode, realtime, max_steps, start_paused)

    def pause(self) -> dict:
        """Pause a running rollout."""
        return self._call(self._pause)

    def resume(self) -> dict:
        """Go on with a paused rollout."""
        return self._call(self._resume)

    def step(self) -> dict:
        """One control step of every lane of a paused rollout."""
        return self._call(self._step_paused)

    def reset(self) -> dict:
        """Stop any run and go back to the scene's first frame, with the same target and box."""
        return self._call(self._reset)

    def episode(self) -> dict:
        """The current (or last) run as JSON: scene, box, and per lane its result and every step."""
        return self._call(self._episode)

    def video_frames(self) -> tuple[list[np.ndarray], int]:
        """The run's video frames (lanes stacked, captioned) and the frame rate."""
        lanes, fps = self._call(self._video_material)
        n = max(len(frames) for _, frames in lanes)
        out = []
        for k in range(n):
            parts = []
            for caption, frames in lanes:
                wrist, third = frames[min(k, len(frames) - 1)]
                parts.append((wrist, third, caption))
            out.append(video_frame(parts))
        return out, fps

    def close(self) -> None:
        """Stop the worker, freeing the renderers on its thread."""
        self._worker.close(cleanup=self._shutdown)

    # ------------------------------------------------------------------ worker-side implementation
    def _call(self, fn: Any, *args: Any) -> Any:
        return self._worker.call(fn, *args, timeout=CALL_TIMEOUT_S)

    def _env(self, slot: int, setting: str) -> tuple[Any, ThirdPersonView]:
        from lerobot_bboxpick.sim.env import LegoPickEnv

        if self._env_setting != setting:
            self._close_envs()
            self._env_setting = setting
        while len(self._envs) <= slot:
            # The lane stops the episode at its max_steps; the env's own limit stays out of the way.
            env = LegoPickEnv(setting=setting, episode_length=MAX_STEPS_LIMIT)
            self._envs.append(env)
            self._views.append(ThirdPersonView(env.model))
        return self._envs[slot], self._views[slot]

    def _shutdown(self) -> None:
        # Stop the run first: the worker ticks once more after this job, and must not touch closed envs.
        self._run, self._phase, self._message = None, "closed", "the dashboard has stopped"
        self._close_envs()
        self._publish()

    def _close_envs(self) -> None:
        for env, view in zip(self._envs, self._views, strict=True):
            env.close()
            view.close()
        self._envs, self._views, self._env_setting = [], [], None

    def _require_idle(self, what: str) -> None:
        if self._phase in ("running", "paused"):
            raise RequestError(
                f"cannot {what} while a run is {self._phase}: wait for it to end, or press Reset",
                status=409,
                field="phase",
            )

    def _load_scene(self, setting: str, seed: int) -> dict:
        self._require_idle("load a scene")
        env, view = self._env(0, setting)
        obs, _ = env.reset(seed=seed)
        boxes = np.stack([env.brick_box(i).bbox for i in range(N_BRICKS)])
        box = np.asarray(obs[ENV_BBOX], dtype=np.float32)
        visible = bool(box[2] > box[0] and box[3] > box[1])
        self._scene_version += 1
        assert env.layout is not None
        self._scene = Scene(
            setting=setting,
            seed=seed,
            image=obs[ENV_PIXELS][ENV_CAMERA].copy(),
            brick_boxes=boxes,
            masks=env.render_brick_masks(),
            colors=env.layout.colors,
            target=env.target,
            box=box if visible else None,
            target_source="seed",
            target_iou=1.0 if visible else None,
            version=self._scene_version,
        )
        self._run, self._error = None, None
        self._phase = "ready" if visible else "empty"
        self._message = (
            f"scene {setting} seed {seed}: target brick {env.target} ({env.layout.target_color}); "
            "drag a box or click a brick to choose another"
            if visible
            else f"scene {setting} seed {seed}: the seed's target is out of view; drag a box around a brick"
        )
        self._frames = {
            "scene": encode_jpeg(self._scene.image),
            "third_A": encode_jpeg(view.render(env.data)),
        }
        return self._publish()

    def _set_target(self, box: np.ndarray | None, point: tuple[float, float] | None) -> dict:
        self._require_idle("change the target")
        scene = self._scene
        if scene is None:
            raise RequestError("load a scene before choosing a target", status=409, field="scene")
        if box is not None:
            target, iou = match_brick(box, scene.brick_boxes)
            scene.box, scene.target_source, scene.target_iou = box, "box", iou
        else:
            assert point is not None
            target = brick_at(point, scene.masks)
            # A click designates the brick; its box is the env's projected box of it.
            scene.box, scene.target_source, scene.target_iou = scene.brick_boxes[target].copy(), "click", 1.0
        scene.target = target
        self._run, self._error, self._phase = None, None, "ready"
        self._message = (
            f"target: brick {target} ({scene.colors[target]}), IoU {scene.target_iou:.2f}; press Run"
        )
        return self._publish()

    def _start(
        self, choices: list[PolicyChoice], bbox_mode: str, realtime: bool, max_steps: int, start_paused: bool
    ) -> dict:
        self._require_idle("start a run")
        scene = self._scene
        if scene is None or scene.box is None:
            raise RequestError("load a scene and choose a target before running", status=409, field="scene")
        lanes = []
        for i, choice in enumerate(choices):
            env, view = self._env(i, scene.setting)
            runner = self.catalog.runner(choice, env, slot=i, field=f"policies[{i}]")
            lanes.append(Lane(SLOTS[i], choice, env, runner, view, max_steps=max_steps, bbox_mode=bbox_mode))
        for lane in lanes:
            lane.start(scene.seed, scene.target, scene.box)
        period = 1.0 / lanes[0].env.options.fps
        self._run = Run(lanes, realtime, max_steps, bbox_mode, period, due=time.perf_counter())
        self._error = None
        self._phase = "paused" if start_paused else "running"
        names = " vs ".join(c.label for c in choices)
        self._message = f"paused: {names} (Step advances)" if start_paused else f"running: {names}"
        self._publish_lanes()
        return self._publish()

    def _pause(self) -> dict:
        if self._phase != "running":
            raise RequestError(f"nothing to pause: the dashboard is {self._phase}", status=409, field="phase")
        self._phase, self._message = "paused", "paused: Step advances one control step, Resume goes on"
        return self._publish()

    def _resume(self) -> dict:
        if self._phase != "paused":
            raise RequestError(
                f"nothing to resume: the dashboard is {self._phase}", status=409, field="phase"
            )
        assert self._run is not None
        self._phase, self._run.due = "running", time.perf_counter()
        self._message = "running"
        return self._publish()

    def _step_paused(self) -> dict:
        if self._phase != "paused":
            raise RequestError(
                f"Step works on a paused run; the dashboard is {self._phase} "
                "(Run with 'start paused', or Pause)",
                status=409,
                field="phase",
            )
        return self._advance()

    def _reset(self) -> dict:
        if self._scene is None:
            raise RequestError("nothing to reset: load a scene first", status=409, field="scene")
        self._run, self._error = None, None
        self._phase = "ready" if self._scene.box is not None else "empty"
        self._message = "reset to the scene's first frame"
        self._frames = {k: v for k, v in self._frames.items() if k in ("scene", "third_A")}
        return self._publish()

    def _tick(self) -> float | None:
        run = self._run
        if self._phase != "running" or run is None:
            return None
        now = time.perf_counter()
        if run.realtime and now < run.due:
            return run.due - now
        self._advance()
        if not run.realtime:
            return 0.0
        # Real time: one tick per control period; a slow tick is not caught up with a burst.
        run.due = max(run.due + run.period_s, time.perf_counter() - run.period_s)
        return max(0.0, run.due - time.perf_counter())

    def _advance(self) -> dict:
        run = self._run
        assert run is not None
        for lane in run.lanes:
            lane.step()
        run.tick += 1
        run.tick_times.append(time.perf_counter())
        if run.done:
            self._phase = "done"
            self._message = "; ".join(
                f"{lane.slot} {lane.choice.label}: {lane.outcome}" for lane in run.lanes
            )
        self._publish_lanes()
        return self._publish()

    def _tick_failed(self, error: BaseException) -> None:
        self._phase, self._error = "error", f"{type(error).__name__}: {error}"
        self._message = f"the run stopped: {self._error}"
        self._publish()

    def _publish_lanes(self) -> None:
        assert self._run is not None
        for lane in self._run.lanes:
            self._frames[f"wrist_{lane.slot}"], self._frames[f"third_{lane.slot}"] = lane.frames[-1]

    def _status(self) -> dict:
        run = self._run
        status: dict[str, Any] = {
            "phase": self._phase,
            "message": self._message,
            "error": self._error,
            "scene": None if self._scene is None else self._scene.as_json(),
            "run": None,
        }
        if run is not None:
            recent = run.tick_times[-21:]
            fps = (
                (len(recent) - 1) / (recent[-1] - recent[0])
                if len(recent) > 1 and recent[-1] > recent[0]
                else None
            )
            status["run"] = {
                "tick": run.tick,
                "realtime": run.realtime,
                "max_steps": run.max_steps,
                "bbox_mode": run.bbox_mode,
                "steps_per_s": fps,
                "lanes": [
                    {
                        "slot": lane.slot,
                        "policy": lane.choice.id,
                        "label": lane.choice.label,
                        "steps": lane.steps,
                        "outcome": lane.outcome,
                        "done": lane.done,
                        "policy_bbox": [float(v) for v in lane.policy_bbox],
                    }
                    for lane in run.lanes
                ],
            }
        return status

    def _publish(self) -> dict:
        self._version += 1
        status = {**self._status(), "version": self._version}
        with self._published:
            self._snapshot = Snapshot(self._version, status, dict(self._frames))
            self._published.notify_all()
        return status

    def _episode(self) -> dict:
        run, scene = self._run, self._scene
        if run is None or scene is None:
            raise RequestError("no run to download: run a policy first", status=404, field="run")
        return {
            "format": EPISODE_FORMAT,
            "setting": scene.setting,
            "seed": scene.seed,
            "target": scene.target,
            "target_color": scene.colors[scene.target],
            "drawn_box": None if scene.box is None else [float(v) for v in scene.box],
            "target_source": scene.target_source,
            "target_iou": scene.target_iou,
            "bbox_mode": run.bbox_mode,
            "max_steps": run.max_steps,
            "realtime": run.realtime,
            "fps": run.lanes[0].env.options.fps,
            "phase": self._phase,
            "lanes": [
                {**lane.summary(), "steps_log": [r.as_json() for r in lane.records]} for lane in run.lanes
            ],
        }

    def _video_material(self) -> tuple[list[tuple[str, list[tuple[bytes, bytes]]]], int]:
        run = self._run
        if run is None:
            raise RequestError("no run to download: run a policy first", status=404, field="run")
        lanes = [
            (
                f"{lane.slot}: {lane.choice.label} - {lane.outcome if lane.done else 'running'}",
                list(lane.frames),
            )
            for lane in run.lanes
        ]
        return lanes, run.lanes[0].env.options.fps


def default_session(checkpoints_dir: Path | None = None) -> DashboardSession:
    """A session over the policies found under ``checkpoints_dir`` (and the expert)."""
    return DashboardSession(PolicyCatalog(checkpoints_dir))
