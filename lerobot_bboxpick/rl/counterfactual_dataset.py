"""``bboxpick-counterfactual``: action chunks labelled with their true outcome, from saved simulator states.

    bboxpick-counterfactual --policy_path=examples/bbox_diffusion_lego_pick --episodes=6 \
        --out_dir=outputs/counterfactual --workers=2            # --ray_address=auto: on a Ray cluster

The paper's conclusion (section 7) asks for what a real robot cannot give: several actions tried from
*the same* state, each followed to its outcome. For every episode (setting x seed, training seeds) the
policy runs closed loop; at every ``branch_every``-th chunk boundary from ``first_branch_chunk`` (at
most ``max_points`` per episode) the simulator is saved (``rl.counterfactual.snapshot``) and each
candidate chunk is executed from the restored state, after which the policy finishes the episode
(``run_branch``). Candidates:

* ``policy``: the chunk the policy samples there (the base rollout then continues with it);
* ``sample1..K``: ``samples`` more draws from the policy at the same observation;
* one chunk per ``perturbations`` entry and sign (``x:0.03`` -> ``x+0.030``, ``x-0.030``): the policy's
  chunk ramped off along that axis (``rl.chunk_perturbations``);
* ``expert``: the scripted expert's plan from that state (it reads the simulator), when ``expert``.

With ``success_demos`` every branch that picks is also recorded, from its branch point to the pick, as
an episode of the LeRobotDataset ``out_dir/success_demos`` (``rl.branch_demos``: the imitation-data
baseline a critic-based improvement must beat).

Each candidate's label is its Monte-Carlo return from the branch point: the outcome group's terminal
reward (``CriticDataConfig``: pick +1, miss 0, wrong -1) times ``gamma ** (steps to the terminal step)``.
Everything is seeded by the episode seed, the branch point and the candidate, so the same options give
the same dataset (bit for bit, on the same machine and thread count).

Written into ``out_dir``: ``points/<setting>_seed<seed>.npz`` per episode (observations with the
policy's history, candidate chunks, outcomes, returns; ``load_points`` reads them all), ``config.json``
and ``summary.md`` (pick rate per candidate kind and setting). An interrupted run resumes: episodes whose
file exists are skipped (the config must match, or ``--fresh=true``).
"""

import contextlib
import copy
import hashlib
import json
import logging
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import draccus
import numpy as np
import torch
from tqdm import tqdm

from lerobot_bboxpick import seeds
from lerobot_bboxpick.keys import BBOX, STATE, WRIST_IMAGE
from lerobot_bboxpick.parallel import check_ray, worker_pool
from lerobot_bboxpick.rl.branch_demos import PARTS_DIR, BranchFrames, SuccessDemos, aggregate_success_demos
from lerobot_bboxpick.rl.chunk_perturbations import parse_perturbations
from lerobot_bboxpick.rl.counterfactual import restore, run_branch, snapshot
from lerobot_bboxpick.rl.critic_dataset import GROUP_OF_OUTCOME, CriticDataConfig
from lerobot_bboxpick.rl.rerank import sample_chunks
from lerobot_bboxpick.shipped_checkpoints import FIRST_SHIPPED_CHECKPOINT
from lerobot_bboxpick.sim.layouts import SETTINGS, check_setting
from lerobot_bboxpick.sim.outcome import OUTCOMES

log = logging.getLogger(__name__)
POINTS_DIR = "points"
CONFIG_NAME = "config.json"


@dataclass
class CounterfactualConfig:
    """Options of ``bboxpick-counterfactual``."""

    # The bbox_diffusion checkpoint that proposes chunks and finishes every branch (default: the imitation
    # policy docs/counterfactual measured, so their commands reproduce).
    policy_path: Path = FIRST_SHIPPED_CHECKPOINT
    settings: str = ",".join(SETTINGS)
    # Episodes per setting, on seeds seed_start, seed_start + 1, ... (training seeds only).
    episodes: int = 4
    seed_start: int = 1000
    # Chunk boundaries between branch points (1: every chunk), and branch points per episode.
    branch_every: int = 2
    max_points: int = 4
    # The chunk boundary of the first branch point (0: the episode's start). Later starts put the
    # branches where the policy misses, past the approach (near the brick) that every candidate shares.
    first_branch_chunk: int = 0
    # Extra policy samples per branch point.
    samples: int = 2
    # Per-axis perturbations of the policy's chunk, <axis>:<amount> (each tried with + and -).
    perturbations: str = "x:0.03,y:0.03,z:0.03,yaw:0.35"
    expert: bool = True
    # Also record every picking branch as a LeRobotDataset episode (out_dir/success_demos).
    success_demos: bool = False
    # Denoising steps per chunk (None: the checkpoint's); fewer makes every branch cheaper.
    num_inference_steps: int | None = 4
    max_steps: int = 300
    gamma: float = 0.99
    out_dir: Path = Path("outputs/counterfactual")
    workers: int = 2
    ray_address: str | None = None
    # Move an earlier run with other options aside instead of refusing.
    fresh: bool = False
    rewards: CriticDataConfig = field(default_factory=CriticDataConfig)

    def __post_init__(self) -> None:
        self.policy_path = Path(self.policy_path)
        self.out_dir = Path(self.out_dir)
        for name, minimum in (
            ("episodes", 1),
            ("branch_every", 1),
            ("max_points", 1),
            ("first_branch_chunk", 0),
            ("samples", 0),
            ("max_steps", 1),
            ("workers", 1),
        ):
            value = getattr(self, name)
            if not isinstance(value, int) or value < minimum:
                raise ValueError(f"{name}={value!r} must be an integer >= {minimum}")
        if self.num_inference_steps is not None and self.num_inference_steps < 1:
            raise ValueError(f"num_inference_steps={self.num_inference_steps} must be >= 1 (or None)")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma={self.gamma} must be in (0, 1]")
        seeds.check_seeds_in_split(self.seed_start, self.seed_start + self.episodes - 1, "train")
        parse_perturbations(self.perturbations)
        if not self.setting_list:
            raise ValueError(f"settings={self.settings!r} is empty; valid settings: {', '.join(SETTINGS)}")
        if not (self.policy_path / "config.json").is_file():
            raise ValueError(f"policy_path={self.policy_path} is not a checkpoint folder (no config.json)")
        check_ray(self.ray_address)

    @property
    def setting_list(self) -> tuple[str, ...]:
        """The settings named by ``settings``, validated."""
        return tuple(check_setting(s.strip()) for s in str(self.settings).split(",") if s.strip())

    @property
    def candidate_kinds(self) -> list[str]:
        """Names of the candidates tried at every branch point, in order."""
        kinds = ["policy"] + [f"sample{i + 1}" for i in range(self.samples)]
        kinds += [p.name for p in parse_perturbations(self.perturbations)]
        return kinds + (["expert"] if self.expert else [])

    def run_key(self) -> dict:
        """What decides the dataset (a resumed run must match it)."""
        from lerobot_bboxpick.eval.suite import weights_digest

        key = {
            "weights": weights_digest(str(self.policy_path)),
            "branch_every": self.branch_every,
            "max_points": self.max_points,
            "candidates": self.candidate_kinds,
            "num_inference_steps": self.num_inference_steps,
            "max_steps": self.max_steps,
            "gamma": self.gamma,
            "rewards": [self.rewards.reward_of(g) for g in ("success", "miss", "wrong")],
        }
        if self.success_demos:  # earlier runs' keys stay valid
            key["success_demos"] = True
        if self.first_branch_chunk:
            key["first_branch_chunk"] = self.first_branch_chunk
        return key


def mc_return(outcome: str, steps: int, gamma: float, rewards: CriticDataConfig) -> float:
    """Discounted terminal reward of a branch that ran ``steps`` env steps and ended with ``outcome``."""
    return rewards.reward_of(GROUP_OF_OUTCOME[outcome]) * gamma ** max(steps - 1, 0)


def _derived_seed(*parts: int) -> int:
    """A 63-bit seed from integers (stable across processes, unlike ``hash``)."""
    digest = hashlib.sha256(",".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(digest[:8], "little") & (2**63 - 1)


class _PolicyState:
    """Save and put back a ``bbox_diffusion`` policy's rollout state (observation history, queued
    actions): the policy-side half of a counterfactual branch (the env's half is the snapshot)."""

    def __init__(self, policy: Any) -> None:
        self.queues = copy.deepcopy(policy._queues)
        self.actions = copy.deepcopy(policy._actions)

    def restore(self, policy: Any) -> None:
        policy._queues = copy.deepcopy(self.queues)
        policy._actions = copy.deepcopy(self.actions)


def _observe(policy: Any, batch: dict) -> None:
    """Append one preprocessed observation to the policy's history without predicting."""
    from lerobot.policies.utils import populate_queues

    policy._queues = populate_queues(policy._queues, {k: v for k, v in batch.items() if k in policy._queues})


class EpisodeBrancher:
    """Runs one episode of the base policy and branches at its chunk boundaries (see the module
    docstring); installed as the policy's ``chunk_selector`` for the base rollout."""

    def __init__(
        self, cfg: CounterfactualConfig, runner: Any, env: Any, seed: int, demos: SuccessDemos | None = None
    ) -> None:
        self.cfg, self.runner, self.env, self.seed = cfg, runner, env, seed
        self.demos = demos  # where picking branches go, when recorded
        self.perturbations = parse_perturbations(cfg.perturbations)
        self.n_exec = runner.policy.config.n_action_steps
        self.chunk_index = 0
        self.points: list[dict] = []
        self.task = ""

    def _branch_policy_fn(self, state: _PolicyState, chunk_len: int, branch_seed: int):
        """Policy callback and step hook for one branch: the policy resumes from ``state`` and sees the
        observations of the executed candidate steps as its history."""
        policy = self.runner.policy
        state.restore(policy)
        policy._actions.clear()
        torch.manual_seed(branch_seed)
        seen = {"steps": 0}

        def on_step(action: np.ndarray, obs: dict, reward: float, info: dict) -> None:
            seen["steps"] += 1
            if seen["steps"] < chunk_len:  # the last one reaches the policy through policy_fn
                _observe(policy, self.runner.observation_batch(obs, self.task))

        return (lambda obs: self.runner.act(obs, self.task)), on_step

    def _candidates(self, stacked: dict, chunk: np.ndarray, point: int) -> np.ndarray:
        policy = self.runner.policy
        out = [chunk]
        if self.cfg.samples:
            gen = torch.Generator().manual_seed(_derived_seed(self.seed, point, 1))
            out += list(sample_chunks(policy, stacked, self.cfg.samples, gen)[0].double().numpy())
        out += [p.apply(chunk) for p in self.perturbations]
        if self.cfg.expert:
            from lerobot_bboxpick.sim.expert import ScriptedExpert

            plan = ScriptedExpert(vary=False).plan(self.env)
            rows = np.minimum(np.arange(len(chunk)), len(plan) - 1)
            out.append(plan[rows].astype(np.float64))
        return np.stack(out)

    def __call__(self, policy: Any, stacked: dict, generator: torch.Generator | None) -> torch.Tensor:
        """Chunk selector: the policy's own chunk; at branch points, first try every candidate."""
        index = self.chunk_index
        self.chunk_index += 1
        gen = torch.Generator().manual_seed(_derived_seed(self.seed, index, 0))
        chunk = policy.predict_action_chunk(stacked, generator=gen)
        since_first = index - self.cfg.first_branch_chunk
        is_point = (
            since_first >= 0
            and since_first % self.cfg.branch_every == 0
            and len(self.points) < self.cfg.max_points
        )
        if not is_point:
            return chunk
        env = self.env
        snap, state = snapshot(env), _PolicyState(policy)
        remaining = self.cfg.max_steps - snap.steps
        candidates = self._candidates(stacked, chunk[0].double().numpy(), len(self.points))
        policy.chunk_selector = None  # branches finish with the plain policy
        outcomes, steps, returns = [], [], []
        for c, cand in enumerate(candidates):
            first = cand[: min(self.n_exec, remaining)]
            policy_fn, on_step = self._branch_policy_fn(
                state, len(first), _derived_seed(self.seed, len(self.points), 2, c)
            )
            frames = BranchFrames(env, snap.observation, self.task) if self.demos is not None else None
            hook = on_step if frames is None else frames.hook(on_step)
            result = run_branch(env, snap, first, policy_fn, max(remaining, len(first)), hook)
            if frames is not None and result.outcome == "pick":
                self.demos.add(frames.frames)
            outcomes.append(OUTCOMES.index(result.outcome))
            steps.append(result.steps)
            returns.append(mc_return(result.outcome, result.steps, self.cfg.gamma, self.cfg.rewards))
        restore(env, snap)
        state.restore(policy)
        policy.chunk_selector = self
        torch.manual_seed(_derived_seed(self.seed, index, 3))
        self.points.append(
            {
                "step": snap.steps,
                "image": (stacked[WRIST_IMAGE][0].clamp(0, 1) * 255).round().to(torch.uint8).numpy(),
                "state": stacked[STATE][0].double().numpy(),
                "bbox": stacked[BBOX][0].float().numpy(),
                "candidates": candidates.astype(np.float32),
                "outcome": np.array(outcomes, dtype=np.int8),
                "steps": np.array(steps, dtype=np.int16),
                "ret": np.array(returns, dtype=np.float32),
            }
        )
        return chunk


def branch_episode(task: dict) -> dict:
    """One episode with its branch points (runs in a worker); writes ``task["path"]`` (npz)."""
    from lerobot_bboxpick.eval.suite import load_runner
    from lerobot_bboxpick.sim.env import LegoPickEnv

    torch.set_num_threads(task.get("threads", 1))
    cfg: CounterfactualConfig = task["cfg"]
    t0 = time.perf_counter()
    env = LegoPickEnv(setting=task["setting"], episode_length=cfg.max_steps)
    runner = load_runner(str(cfg.policy_path), None, env, cfg.num_inference_steps)
    seed = task["seed"]
    torch.manual_seed(seed)
    obs, info = env.reset(seed=seed)
    runner.reset()
    demos = SuccessDemos(Path(task["demos"])) if cfg.success_demos else None
    brancher = EpisodeBrancher(cfg, runner, env, seed, demos)
    brancher.task = info["task"]
    runner.policy.chunk_selector = brancher
    try:
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(runner.act(obs, brancher.task))
            done = terminated or truncated
    finally:
        runner.policy.chunk_selector = None
    env.close()
    if demos is not None:
        demos.finalize()  # before the npz: a file that exists means the episode is complete
    points = brancher.points
    arrays = {k: np.stack([p[k] for p in points]) for k in points[0]} if points else {}
    path = Path(task["path"])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(
        tmp,
        **arrays,
        setting=np.array(task["setting"]),
        seed=np.array(seed),
        base_outcome=np.array(OUTCOMES.index(info["outcome"])),
    )
    tmp.rename(path)  # a file that exists is complete (resume relies on it)
    return {
        "setting": task["setting"],
        "seed": seed,
        "points": len(points),
        "base_outcome": info["outcome"],
        "success_demos": demos.episodes if demos is not None else 0,
        "seconds": round(time.perf_counter() - t0, 1),
    }


# ---------------------------------------------------------------- reading
@dataclass
class CounterfactualPoints:
    """Every branch point of a run (rows), its candidates (columns) and their labels."""

    image: np.ndarray  # (P, n_obs, 3, H, W) uint8, the policy's observation history
    state: np.ndarray  # (P, n_obs, 10) absolute TCP poses
    bbox: np.ndarray  # (P, n_obs, 4)
    candidates: np.ndarray  # (P, C, horizon, 10) absolute chunks
    outcome: np.ndarray  # (P, C) index into OUTCOMES
    steps: np.ndarray  # (P, C) env steps the branch ran
    ret: np.ndarray  # (P, C) Monte-Carlo return
    step: np.ndarray  # (P,) env step of the branch point
    setting: np.ndarray  # (P,) str
    seed: np.ndarray  # (P,) episode seed
    kinds: list[str]  # (C,) candidate names

    def __len__(self) -> int:
        return len(self.state)

    @property
    def base_pose(self) -> np.ndarray:
        """(P, 10) the latest observed TCP pose: what relative chunks are relative to."""
        return self.state[:, -1]

    def subset(self, mask: np.ndarray) -> "CounterfactualPoints":
        """The rows ``mask`` selects."""
        return CounterfactualPoints(
            **{k: getattr(self, k)[mask] for k in self.__dataclass_fields__ if k != "kinds"},
            kinds=self.kinds,
        )


def load_points(out_dir: str | Path) -> CounterfactualPoints:
    """All branch points written by ``bboxpick-counterfactual`` into ``out_dir``."""
    out_dir = Path(out_dir)
    meta = json.loads((out_dir / CONFIG_NAME).read_text())
    parts: dict[str, list] = {}
    for path in sorted((out_dir / POINTS_DIR).glob("*_seed*.npz")):
        if path.name.endswith(".tmp.npz"):
            continue
        with np.load(path) as z:
            if "candidates" not in z:
                continue  # an episode without branch points
            n = len(z["step"])
            for k in ("image", "state", "bbox", "candidates", "outcome", "steps", "ret", "step"):
                parts.setdefault(k, []).append(z[k])
            parts.setdefault("setting", []).append(np.full(n, str(z["setting"])))
            parts.setdefault("seed", []).append(np.full(n, int(z["seed"])))
    if not parts:
        raise FileNotFoundError(f"no branch points in {out_dir / POINTS_DIR}: run bboxpick-counterfactual")
    return CounterfactualPoints(
        **{k: np.concatenate(v) for k, v in parts.items()}, kinds=meta["run_key"]["candidates"]
    )


def summary_table(points: CounterfactualPoints) -> str:
    """Markdown: pick / wrong rate and mean return per candidate kind, overall and per setting."""
    settings = sorted(set(points.setting.tolist()))
    pick = OUTCOMES.index("pick")
    wrong = OUTCOMES.index("wrong")
    head = "| candidate | Pick (all) | Wrong (all) | mean return | " + " | ".join(
        f"Pick {s}" for s in settings
    )
    lines = [head + " |", "|" + "---|" * (4 + len(settings))]
    for c, kind in enumerate(points.kinds):
        o = points.outcome[:, c]
        cells = [
            f"{np.mean(o == pick):.0%}",
            f"{np.mean(o == wrong):.0%}",
            f"{points.ret[:, c].mean():+.3f}",
        ]
        cells += [f"{np.mean(o[points.setting == s] == pick):.0%}" for s in settings]
        lines.append(f"| {kind} | " + " | ".join(cells) + " |")
    best = points.ret.max(1)
    lines.append(
        f"\n{len(points)} branch points, {points.candidates.shape[1]} candidates each; the best candidate "
        f"picks at {np.mean(best > 0):.0%} of points, the policy's own chunk at "
        f"{np.mean(points.outcome[:, 0] == pick):.0%}; points where candidates disagree (some pick, some "
        f"not): {np.mean((points.outcome == pick).any(1) & ~(points.outcome == pick).all(1)):.0%}."
    )
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- parent side
def _prepare(cfg: CounterfactualConfig) -> dict:
    key = cfg.run_key()
    meta_path = cfg.out_dir / CONFIG_NAME
    if meta_path.is_file():
        old = json.loads(meta_path.read_text()).get("run_key")
        if old != key:
            if not cfg.fresh:
                raise ValueError(
                    f"out_dir={cfg.out_dir} holds a counterfactual run with other options ({old}); this run "
                    f"is {key}. Choose another --out_dir or pass --fresh=true to move it aside"
                )
            aside = cfg.out_dir.with_name(f"{cfg.out_dir.name}.{time.strftime('%Y%m%d-%H%M%S')}")
            shutil.move(str(cfg.out_dir), aside)
            log.warning("moved the earlier run aside to %s", aside)
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    meta_path.write_text(json.dumps({"run_key": key, "config": draccus.encode(cfg)}, indent=1, default=str))
    return key


def run_counterfactual(cfg: CounterfactualConfig) -> Path:
    """Run (or resume) every episode, then write ``summary.md``; returns its path."""
    import multiprocessing as mp

    _prepare(cfg)
    threads = max(1, (mp.cpu_count() or 1) // cfg.workers)
    tasks = []
    for setting in cfg.setting_list:
        for k in range(cfg.episodes):
            name = f"{setting}_seed{cfg.seed_start + k}"
            path = cfg.out_dir / POINTS_DIR / f"{name}.npz"
            if not path.is_file():
                tasks.append(
                    {
                        "cfg": cfg,
                        "setting": setting,
                        "seed": cfg.seed_start + k,
                        "path": str(path),
                        "demos": str(cfg.out_dir / PARTS_DIR / name),
                        "threads": threads,
                    }
                )
    total = len(cfg.setting_list) * cfg.episodes
    local = cfg.workers == 1 and not cfg.ray_address
    with (
        tqdm(total=total, initial=total - len(tasks), desc="counterfactual", unit="ep") as bar,
        contextlib.nullcontext()
        if local
        else worker_pool(cfg.workers, cfg.ray_address, maxtasksperchild=None) as pool,
    ):
        results = (
            map(branch_episode, tasks) if local else pool.imap_unordered(branch_episode, tasks, chunksize=1)
        )
        for r in results:
            bar.set_postfix_str(f"{r['setting']} seed {r['seed']}: {r['points']} points")
            bar.update()
    summary = cfg.out_dir / "summary.md"
    summary.write_text(summary_table(load_points(cfg.out_dir)))
    if cfg.success_demos:
        demos = aggregate_success_demos(cfg.out_dir)
        log.info("picking branches as episodes: %s", demos or "none (no branch picked)")
    return summary


@draccus.wrap()
def main(cfg: CounterfactualConfig) -> None:
    """Entry point of ``bboxpick-counterfactual``."""
    logging.basicConfig(level=logging.INFO)
    summary = run_counterfactual(cfg)
    print(summary.read_text())
    print(f"written: {summary}")


if __name__ == "__main__":
    main()
