"""``bboxpick-rollouts``: closed-loop episodes of a trained policy, failures kept, into a LeRobotDataset.

    bboxpick-rollouts --policy_path=outputs/train/checkpoints/last/pretrained_model \
        --repo_id=local/rollouts --root=outputs/datasets/rollouts --episodes=20 --workers=2 \
        --merge_with=outputs/datasets/expert --stats_png=outputs/datasets/rollouts_stats.png

Data for offline RL (the IQL critic, ``lerobot_bboxpick.rl``): every episode is kept whatever its
outcome and labelled with it (``episode.outcome``; ``next.success``, ``next.done`` and the env's sparse
reward per frame). Frames are ``bboxpick-collect``'s schema: frame ``t`` holds the observation before
step ``t`` and the absolute pose10 action the policy returned and the env executed at step ``t``.

* **Episodes** run as ``bboxpick-suite`` runs them (``eval.rollout.rollout``: LeRobot's observation
  preprocessing, the checkpoint's processors, the oracle bbox, the policy's noise seeded by the episode
  seed, the episode ends at a pick or wrong pick or after ``--max_steps``), so a rollout dataset holds
  exactly the behaviour the suite scores.
* **Seeds** come from the training split (0-4999, ``lerobot_bboxpick.seeds``): the critic learns from
  them. ``--seed_start`` defaults to 1000, past the first expert demonstrations; evaluation seeds are
  refused. ``--episodes`` is per setting: seeds ``seed_start ...`` cycle through ``--settings``
  (``seed % len(settings)`` picks the setting), as in ``bboxpick-collect``.
* **Sharding, resume, workers (local processes, or a Ray cluster with ``--ray_address``), log
  redirection and aggregation** are ``bboxpick-collect``'s (``data.collect``, with a policy recorder
  instead of the expert). Every seed's record carries the run key (checkpoint weights digest, max
  steps, executed steps per chunk); ``--resume=true`` with another checkpoint or options is refused, so
  a dataset never mixes two policies.
* ``--merge_with=<root>``: a dataset of the same schema (expert demos) aggregated first, with LeRobot's
  ``aggregate_datasets``, into ``--root``: one dataset with demos and rollouts.
* ``--stats_png``: episodes per outcome and setting, and episode lengths per outcome (``viz``).
"""

import dataclasses
import json
import logging
import multiprocessing as mp
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import draccus
import numpy as np

from lerobot_bboxpick.data.collect import (
    SHARD_SIZE,
    CollectConfig,
    EpisodeRecorder,
    close_episode,
    collect,
    step_frame,
)
from lerobot_bboxpick.data.features import (
    EPISODE_OUTCOME,
    EPISODE_SETTING,
    FPS,
    ROBOT_TYPE,
    dataset_features,
)
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.outcome import OUTCOMES

DEFAULT_SEED_START = 1000
log = logging.getLogger(__name__)


@dataclass
class RolloutsConfig:
    """Options of ``bboxpick-rollouts``."""

    # The checkpoint to roll out: a ``save_pretrained`` folder (``.../pretrained_model``).
    policy_path: Path | None = None
    repo_id: str = "local/lego_pick_rollouts"
    root: Path = Path("outputs/datasets/lego_pick_rollouts")
    # Comma-separated settings; episode seeds cycle through them
    # (the seed modulo their count picks the setting).
    settings: str = ",".join(SETTINGS)
    # Episodes per setting (all kept, whatever their outcome).
    episodes: int = 10
    # First seed; every seed used must be a training seed (0-4999).
    seed_start: int = DEFAULT_SEED_START
    # Env steps before an episode is cut (outcome as tracked then).
    max_steps: int = 300
    # Executed steps per predicted chunk; None keeps the checkpoint's own setting.
    n_action_steps: int | None = None
    # Denoising steps per chunk (as bboxpick-suite --num_inference_steps); None keeps the checkpoint's.
    num_inference_steps: int | None = None
    workers: int = 1
    # Ray cluster the workers run on: "auto", "ray://<head>:10001" or "local"; None: local processes.
    # root and policy_path must be on a file system every node shares (docs/ray.md).
    ray_address: str | None = None
    resume: bool = False
    # Episodes per shard: the most work an interruption can lose.
    shard_size: int = SHARD_SIZE
    # A dataset of the same schema (e.g. bboxpick-collect's expert demos) merged into root first.
    merge_with: Path | None = None
    # Where to draw the dataset's outcome statistics (PNG); None: no plot.
    stats_png: Path | None = None
    push_to_hub: bool = False
    # Where the workers' own output goes; None: <root>.collect/workers.log.
    log_file: Path | None = None

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        if self.policy_path is None or not (Path(self.policy_path) / "config.json").is_file():
            raise ValueError(
                f"policy_path={self.policy_path!r} must be a checkpoint folder with config.json "
                "(e.g. outputs/train/checkpoints/last/pretrained_model)"
            )
        self.policy_path = Path(self.policy_path)
        for name, minimum in (("max_steps", 1), ("episodes", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < minimum:
                raise ValueError(f"{name}={value!r} must be an integer >= {minimum}")
        for name in ("n_action_steps", "num_inference_steps"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)!r} must be >= 1 (or None: the policy's)")
        if self.merge_with is not None:
            self.merge_with = Path(self.merge_with)
            check_mergeable(self.merge_with)
            if self.merge_with.resolve() == self.root.resolve():
                raise ValueError(f"merge_with={self.merge_with} must not be root itself")
        self.stats_png = Path(self.stats_png) if self.stats_png is not None else None
        self.collect_config()  # validates settings, workers, shard_size and the seeds (training split)

    def collect_config(self) -> CollectConfig:
        """The ``bboxpick-collect`` options of this run: training seeds, every episode kept."""
        per_setting = CollectConfig(
            repo_id=self.repo_id,
            root=self.root,
            settings=self.settings,
            episodes=self.episodes,
            split="train",
            seed_start=self.seed_start,
            workers=self.workers,
            ray_address=self.ray_address,
            keep_failed=True,
            resume=self.resume,
            shard_size=self.shard_size,
            push_to_hub=self.push_to_hub,
            log_file=self.log_file,
        )
        # Seeds cycle through the settings: episodes x settings consecutive seeds, ``episodes`` of each.
        return dataclasses.replace(per_setting, episodes=self.episodes * len(per_setting.setting_list))


def check_mergeable(root: Path) -> None:
    """Raise a ValueError naming ``merge_with`` unless ``root`` is a LeRobotDataset of our schema."""
    info_path = root / "meta" / "info.json"
    if not info_path.is_file():
        raise ValueError(f"merge_with={root} is not a LeRobotDataset folder (no meta/info.json)")
    info = json.loads(info_path.read_text())
    missing = sorted(set(dataset_features()) - set(info.get("features", {})))
    if missing or info.get("fps") != FPS or info.get("robot_type") != ROBOT_TYPE:
        raise ValueError(
            f"merge_with={root} is not a lerobot_bboxpick dataset (fps {FPS}, robot_type {ROBOT_TYPE!r}, "
            f"the features of data.features.dataset_features); it has fps {info.get('fps')}, robot_type "
            f"{info.get('robot_type')!r}, missing features {missing}"
        )


@dataclass(frozen=True)
class PolicyRecorder(EpisodeRecorder):
    """A checkpoint's closed-loop episodes, run by ``eval.rollout.rollout`` as the suite runs them."""

    policy_path: str
    max_steps: int = 300
    n_action_steps: int | None = None
    num_inference_steps: int | None = None
    # Torch threads per worker.
    threads: int = 1
    run_key: dict | None = None

    def make_env(self, setting: str) -> Any:
        """The suite's env: an episode ends at a pick or wrong pick, or after ``max_steps``."""
        from lerobot_bboxpick.sim.env import LegoPickEnv

        return LegoPickEnv(setting=setting, episode_length=self.max_steps)

    def __call__(self, env: Any, seed: int) -> tuple[list[dict], str]:
        """One rollout of seed ``seed`` (policy noise seeded by it too), every step as a frame."""
        import torch

        from lerobot_bboxpick.eval.rollout import rollout
        from lerobot_bboxpick.eval.suite import load_runner

        torch.set_num_threads(self.threads)
        runner = load_runner(self.policy_path, self.n_action_steps, env, self.num_inference_steps)
        frames: list[dict] = []

        def keep(obs: dict, info: dict, action: np.ndarray, reward: float, next_info: dict) -> None:
            frames.append(step_frame(obs, info, action, reward, next_info))

        result = rollout(runner, env.options.setting, seed, policy_seed=seed, env=env, on_step=keep)
        return close_episode(frames, result["outcome"])


def policy_recorder(
    cfg: RolloutsConfig, recorder_class: type[PolicyRecorder] = PolicyRecorder, **options: Any
) -> PolicyRecorder:
    """The recorder of ``cfg`` (a ``recorder_class`` with ``options``), with the suite's run key of the
    checkpoint and options, and ``options`` in the key too."""
    from lerobot_bboxpick.eval.suite import SuiteConfig, run_key

    path = str(cfg.policy_path)
    suite = SuiteConfig(
        policies=path,
        max_steps=cfg.max_steps,
        n_action_steps=cfg.n_action_steps,
        num_inference_steps=cfg.num_inference_steps,
    )
    key = run_key(suite, path) | {
        k: dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v for k, v in options.items()
    }
    return recorder_class(
        policy_path=path,
        max_steps=cfg.max_steps,
        n_action_steps=cfg.n_action_steps,
        num_inference_steps=cfg.num_inference_steps,
        threads=max(1, (mp.cpu_count() or 1) // cfg.workers),
        run_key=key,
        **options,
    )


def record_rollouts(cfg: RolloutsConfig) -> dict:
    """Record (or resume) the rollouts, merge, aggregate into ``cfg.root``; returns a summary."""
    collect_cfg = cfg.collect_config()
    recorder = policy_recorder(cfg)
    merge_with = [cfg.merge_with] if cfg.merge_with is not None else []
    summary = collect(collect_cfg, recorder=recorder, merge_with=merge_with)
    summary["merged_with"] = str(cfg.merge_with) if cfg.merge_with is not None else None
    if cfg.stats_png is not None:
        summary["stats_png"] = str(plot_outcome_stats(cfg.repo_id, cfg.root, cfg.stats_png))
    return summary


def episode_stats(repo_id: str, root: str | Path) -> list[dict]:
    """One record per episode of a dataset of our schema: setting, outcome and length (no video decoding).

    A code of -1 (not known) reads as ``"unknown"``.
    """
    from lerobot_bboxpick.data.replay import load_dataset

    dataset = load_dataset(repo_id, root)
    cols = dataset.hf_dataset.select_columns(["episode_index", EPISODE_SETTING, EPISODE_OUTCOME])
    cols = cols.with_format("numpy")[:]
    episode = np.asarray(cols["episode_index"]).ravel()
    setting = np.asarray(cols[EPISODE_SETTING]).ravel()
    outcome = np.asarray(cols[EPISODE_OUTCOME]).ravel()
    records = []
    for e in np.unique(episode):
        rows = np.flatnonzero(episode == e)
        s, o = int(setting[rows[0]]), int(outcome[rows[0]])
        records.append(
            {
                "episode": int(e),
                "setting": SETTINGS[s] if s >= 0 else "unknown",
                "outcome": OUTCOMES[o] if o >= 0 else "unknown",
                "length": len(rows),
            }
        )
    return records


def plot_outcome_stats(repo_id: str, root: str | Path, png: str | Path) -> Path:
    """Draw a dataset's statistics (episodes per outcome and setting, lengths per outcome) into ``png``."""
    from lerobot_bboxpick.viz import outcome_stats_figure

    return outcome_stats_figure(episode_stats(repo_id, root), OUTCOMES, Path(png))


@draccus.wrap()
def main(cfg: RolloutsConfig) -> None:
    """Entry point of ``bboxpick-rollouts``."""
    logging.basicConfig(level=logging.INFO)
    summary = record_rollouts(cfg)
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
