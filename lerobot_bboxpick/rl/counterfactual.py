"""Counterfactual simulation: save a ``LegoPickEnv`` mid-episode, restore it, and run another branch.

``snapshot(env)`` captures everything that decides the env's future at a step boundary (e.g. where a
policy starts a new action chunk); ``restore(env, snap)`` puts it back, into the same env or into any env
built with the same options (another episode of it too: the scene is the same MjModel for every seed, and
the per-episode appearance the randomiser writes into the model travels with the snapshot).
``run_branch`` restores, executes a given chunk, lets a policy finish the episode and scores it.

What a snapshot holds, and why:

* MuJoCo's integration state (``mj_getState(..., mjSTATE_INTEGRATION)``: time, qpos, qvel, act, ctrl,
  warm start, applied forces, ...) **and a full copy of ``MjData``**. The scene enables MuJoCo's sleeping
  (``robot.xml``: bricks at rest sleep), and then the integration state is not the whole state: a
  sleeping body's kinematics are not recomputed, and it is woken when its recomputed pose differs from the
  stored ``xpos``/``xquat``, so derived arrays (and ``tree_asleep``, in no ``mjtState``) steer the future.
  ``mj_setState`` + ``mj_forward`` alone replays a continuation only to ~1e-7 m (pixels differ);
  ``mj_copyData`` replays it bit for bit. The integration-state vector is kept as the checked summary.
* The model fields the randomiser writes per episode (light, table and brick colours).
* The env's Python-side episode state (``EPISODE_STATE``): step counter, the commanded joint targets,
  TCP pose and gripper width the next step ramps from, the outcome tracker (holds, touches, rise,
  decided brick, peak brick speed), the layout (target), seed, task text, the last frame and bbox (what
  ``render()`` and the policy saw) and the env's own RNG (it draws the seed of ``reset(seed=None)``).
  The IK controller keeps nothing between steps (each solve starts from the commanded joints).

Policy-side state (a diffusion policy's action queue and observation history, its noise RNG, the scripted
expert's plan index) is the caller's: ``policy_fn`` owns it.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import mujoco
import numpy as np

from lerobot_bboxpick.keys import ENV_BBOX, ENV_CAMERA, ENV_PIXELS, ENV_STATE
from lerobot_bboxpick.sim.camera import BoxProjection
from lerobot_bboxpick.sim.env import ACTION_DIM, LegoPickEnv
from lerobot_bboxpick.sim.layouts import Layout
from lerobot_bboxpick.sim.outcome import OutcomeTracker

_STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
# The MjModel fields ``Randomizer.apply`` writes at every reset (per-episode appearance).
_APPEARANCE_FIELDS = ("light_dir", "light_diffuse", "mat_rgba", "geom_rgba")
# LegoPickEnv attributes that change during an episode (tests check no new one goes unnoticed).
EPISODE_STATE = (
    "_steps",
    "_q_cmd",
    "_T_cmd",
    "_width_cmd",
    "_tracker",
    "layout",
    "episode_seed",
    "task_description",
    "task",
    "_last_image",
    "_last_box",
    "_np_random",
    "_np_random_seed",
)

PolicyFn = Callable[[dict], np.ndarray]
# Called after every branch step with (action executed, observation after it, reward, info).
BranchHook = Callable[[np.ndarray, dict, float, dict], None]


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def scene_fingerprint(env: LegoPickEnv) -> str:
    """Digest of what a snapshot needs to be equal in the env it is restored into: the MuJoCo version,
    the env's options and the model's structure and physics (not the per-episode appearance)."""
    m = env.model
    h = hashlib.sha256(f"{mujoco.__version__}|{sorted(asdict(env.options).items())}".encode())
    h.update(np.array([m.nq, m.nv, m.nu, m.na, m.nbody, m.ngeom, m.ntree, m.nmat, m.nlight]).tobytes())
    h.update(bytes(m.names))
    for name in ("body_mass", "body_pos", "geom_size", "geom_pos", "geom_friction", "jnt_range", "cam_fovy"):
        h.update(np.ascontiguousarray(getattr(m, name)).tobytes())
    h.update(np.array([m.opt.timestep, m.opt.integrator, m.opt.enableflags, m.opt.disableflags]).tobytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True, eq=False)
class SimSnapshot:
    """The complete state of a ``LegoPickEnv`` at a step boundary (see the module docstring)."""

    fingerprint: str
    state: np.ndarray  # mj_getState(mjSTATE_INTEGRATION)
    data: mujoco.MjData  # full copy: derived arrays and sleep state included
    appearance: dict[str, np.ndarray]  # _APPEARANCE_FIELDS of the model
    steps: int
    q_cmd: np.ndarray  # (6,) commanded joint targets the next step ramps from
    T_cmd: np.ndarray  # (4, 4) commanded TCP pose (speed limits are measured from it)
    width_cmd: float
    tracker: OutcomeTracker
    layout: Layout
    episode_seed: int | None
    task: str
    image: np.ndarray  # last wrist frame (the observation's pixels)
    box: BoxProjection  # last target bbox
    agent_pos: np.ndarray  # the observation's agent_pos
    np_random: np.random.Generator | None
    np_random_seed: int | None

    @property
    def outcome(self) -> str:
        """The episode's outcome at the snapshot."""
        return self.tracker.outcome

    @property
    def observation(self) -> dict[str, Any]:
        """The observation the env returned at the snapshot (fresh arrays)."""
        return {
            ENV_PIXELS: {ENV_CAMERA: self.image.copy()},
            ENV_STATE: self.agent_pos.copy(),
            ENV_BBOX: self.box.bbox.copy(),
        }


@dataclass(frozen=True)
class BranchResult:
    """One counterfactual branch, scored like a rollout.

    ``reward`` is the env's sparse reward at the branch's last step (``env.step``'s, which
    ``bboxpick-rollouts`` records as ``next.reward``: 1.0 once the outcome is a pick, else 0.0);
    ``success`` is that step's ``is_success`` (``next.success``). The critic's outcome-group reward is
    ``CriticDataConfig().reward_of(GROUP_OF_OUTCOME[outcome])`` (``rl.critic_dataset``).
    """

    outcome: str
    reward: float
    success: bool
    steps: int  # env steps executed in the branch
    actions: np.ndarray  # (steps, 10) absolute pose10 actions executed
    tcp_poses: np.ndarray  # (steps, 4, 4) TCP pose after each step (as env.tcp_pose() reads it)
    terminated: bool  # the env ended the episode (pick, wrong pick, unstable simulation)
    truncated: bool  # cut by the env's episode_length or by max_steps


def snapshot(env: LegoPickEnv) -> SimSnapshot:
    """Save the complete state of ``env`` (after ``reset`` or a ``step``) for ``restore``."""
    if env._tracker is None or env._last_image is None or env._last_box is None or env.layout is None:
        raise RuntimeError("call env.reset() before snapshot(env)")
    state = np.empty(mujoco.mj_stateSize(env.model, _STATE_SPEC))
    mujoco.mj_getState(env.model, env.data, state, _STATE_SPEC)
    box = env._last_box
    return SimSnapshot(
        fingerprint=scene_fingerprint(env),
        state=_frozen(state),
        data=copy.copy(env.data),  # mj_copyData
        appearance={f: _frozen(getattr(env.model, f)) for f in _APPEARANCE_FIELDS},
        steps=env._steps,
        q_cmd=_frozen(env._q_cmd),
        T_cmd=_frozen(env._T_cmd),
        width_cmd=float(env._width_cmd),
        # Deep copy, sharing the (static) scene ids rather than copying them.
        tracker=copy.deepcopy(env._tracker, {id(env._tracker.ids): env._tracker.ids}),
        layout=env.layout,  # frozen; the env builds a new one at every reset
        episode_seed=env.episode_seed,
        task=env.task_description,
        image=_frozen(env._last_image),
        box=BoxProjection(_frozen(box.bbox), box.visibility),
        agent_pos=_frozen(env.agent_pos()),
        np_random=copy.deepcopy(env._np_random),
        np_random_seed=env._np_random_seed,
    )


def restore(env: LegoPickEnv, snap: SimSnapshot) -> None:
    """Put ``env`` back into the state of ``snap``; the next ``env.step`` continues from there.

    ``env`` may be the snapshot's env at any later point, after another ``reset``, or another env built
    with the same options; anything else raises a ValueError. ``snap`` is not changed: restore it again
    for another branch.
    """
    if scene_fingerprint(env) != snap.fingerprint:
        raise ValueError(
            f"snapshot of scene {snap.fingerprint} cannot be restored into an env of scene "
            f"{scene_fingerprint(env)}: restore needs a LegoPickEnv built with the same options "
            "(and the same MuJoCo and scene files) as the one the snapshot was taken in"
        )
    for field, value in snap.appearance.items():
        getattr(env.model, field)[...] = value
    mujoco.mj_copyData(env.data, env.model, snap.data)
    check = np.empty_like(snap.state)
    mujoco.mj_getState(env.model, env.data, check, _STATE_SPEC)
    assert np.array_equal(check, snap.state), "restored MjData does not reproduce the snapshot's state"
    env._steps = snap.steps
    env._q_cmd = snap.q_cmd.copy()
    env._T_cmd = snap.T_cmd.copy()
    env._width_cmd = snap.width_cmd
    env._tracker = copy.deepcopy(snap.tracker, {id(snap.tracker.ids): env.ids})
    env.layout = snap.layout
    env.episode_seed = snap.episode_seed
    env.task_description = env.task = snap.task
    env._last_image = snap.image.copy()
    env._last_box = BoxProjection(snap.box.bbox.copy(), snap.box.visibility)
    env._np_random = copy.deepcopy(snap.np_random)
    env._np_random_seed = snap.np_random_seed


def run_branch(
    env: LegoPickEnv,
    snap: SimSnapshot,
    first_chunk: np.ndarray,
    policy_fn: PolicyFn,
    max_steps: int,
    on_step: BranchHook | None = None,
) -> BranchResult:
    """Restore ``snap`` into ``env``, execute ``first_chunk`` ((k, 10) absolute pose10 actions), then
    ``policy_fn(observation) -> action`` until the env ends the episode or ``max_steps`` steps (counted
    from the snapshot, the chunk included) have run.

    ``policy_fn`` sees the env's observations (the snapshot's own when ``first_chunk`` is empty) and
    must be set up by the caller for this branch (reset, seeded, primed with its observation history).
    """
    chunk = np.asarray(first_chunk, dtype=np.float64)
    if chunk.ndim != 2 or chunk.shape[1] != ACTION_DIM:
        raise ValueError(f"first_chunk must have shape (k, {ACTION_DIM}), got {chunk.shape}")
    if max_steps < max(1, len(chunk)):
        raise ValueError(f"max_steps={max_steps} must be >= 1 and >= the chunk's {len(chunk)} steps")
    if (
        snap.steps >= env.options.episode_length
        or snap.tracker.unstable
        or (env.options.terminate_on_lift and snap.outcome in ("pick", "wrong"))
    ):
        raise ValueError(f"the snapshot ends its episode (step {snap.steps}, outcome {snap.outcome!r})")
    restore(env, snap)
    obs = snap.observation
    actions, poses = [], []
    reward, terminated, truncated, info = 0.0, False, False, {}
    while not (terminated or truncated):
        t = len(actions)
        action = chunk[t] if t < len(chunk) else np.asarray(policy_fn(obs), dtype=np.float64)
        obs, reward, terminated, truncated, info = env.step(action)
        actions.append(action)
        poses.append(env.tcp_pose())
        if on_step is not None:
            on_step(action, obs, float(reward), info)
        truncated = truncated or len(actions) >= max_steps
    return BranchResult(
        outcome=info["outcome"],
        reward=float(reward),
        success=bool(info["is_success"]),
        steps=len(actions),
        actions=np.stack(actions),
        tcp_poses=np.stack(poses),
        terminated=bool(terminated),
        truncated=bool(truncated),
    )
