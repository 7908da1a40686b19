"""``bboxpick-branch-advantages``: Monte-Carlo advantages of counterfactual successes, for advantage-weighted
fine-tuning without a learned critic.

    bboxpick-branch-advantages --data_dir=outputs/cf_main --dataset_root=outputs/cf16/train \
        --out=outputs/cf16/advantages.json
    lerobot-train --policy.path=<IL> --dataset.root=outputs/cf16/train \
        --policy.awr_advantages_path=outputs/cf16/advantages.json --policy.awr_temperature=0.1 ...

A simulator branch point gives what a critic only estimates: from one saved state, several chunks were
executed and followed to their outcome, so ``A = G(branch) - V(point)`` is measured, with ``V`` the mean
return of the candidates the IL policy itself proposed there (its own chunk and its extra draws: the
policy's value at that state). ``bboxpick-counterfactual --success_demos=true`` recorded every picking
branch as an episode; this writes one advantage per episode of the *training* dataset, which is any
number of other episodes (expert demos: advantage 0, weight 1) followed by ``success_demos``'s episodes in
their order, as ``lerobot-edit-dataset --operation.type=merge`` lays them out. Each branch's episode
lengths must match the branch data's step counts, so a dataset that is not laid out this way is refused
rather than weighted wrongly.

With ``awr_temperature`` T, a success from a point where the policy's draws all failed (V = 0) weighs
``exp(G / T)`` (clipped at ``awr_max_weight``), one from a point where they all picked as fast about 1:
the fine-tune imitates most what fixed the policy's failures. Failed branches are not in the data; their
advantage is ``-V <= 0``, weight at most 1, so leaving them out is what a small T does anyway.
"""

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import draccus
import numpy as np

from lerobot_bboxpick.rl.branch_demos import DEMOS_DIR, success_branches
from lerobot_bboxpick.rl.counterfactual_dataset import CounterfactualPoints, load_points

log = logging.getLogger(__name__)


@dataclass
class BranchAdvantagesConfig:
    # A bboxpick-counterfactual out_dir run with --success_demos=true.
    data_dir: Path = Path("outputs/counterfactual")
    # The training dataset: other episodes first, then data_dir/success_demos's episodes, in order.
    dataset_root: Path | None = None
    # Candidates whose mean return is the point's value V (comma-separated kind prefixes).
    baseline: str = "policy,sample"
    out: Path = Path("outputs/branch_advantages.json")


def point_values(points: CounterfactualPoints, baseline: str = "policy,sample") -> np.ndarray:
    """(P,) mean return of each point's candidates whose kind starts with one of ``baseline``'s prefixes."""
    prefixes = tuple(p.strip() for p in baseline.split(",") if p.strip())
    columns = [c for c, kind in enumerate(points.kinds) if kind.startswith(prefixes)]
    if not columns:
        raise ValueError(f"baseline={baseline!r} matches none of the candidate kinds {points.kinds}")
    return points.ret[:, columns].mean(axis=1)


def branch_advantages(points: CounterfactualPoints, baseline: str = "policy,sample") -> np.ndarray:
    """Advantage ``G - V`` of every picking branch, in ``success_demos``'s episode order."""
    values = point_values(points, baseline)
    return np.array([points.ret[p, c] - values[p] for p, c in success_branches(points)], dtype=np.float64)


def episode_lengths(root: Path) -> np.ndarray:
    """Frame count of every episode of the LeRobotDataset at ``root``, in episode order."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    info = json.loads((Path(root) / "meta" / "info.json").read_text())
    meta = LeRobotDatasetMetadata(info.get("repo_id", "local/dataset"), root=root)
    episodes = meta.episodes
    order = np.argsort(np.asarray(episodes["episode_index"]))
    return np.asarray(episodes["length"])[order]


def dataset_advantages(points: CounterfactualPoints, lengths: np.ndarray, baseline: str) -> np.ndarray:
    """One advantage per training episode: 0 for the leading ones, the branch's for the trailing ones,
    after checking that the trailing episodes are the picking branches (same count, same lengths)."""
    branches = success_branches(points)
    if len(lengths) < len(branches):
        raise ValueError(
            f"dataset_root has {len(lengths)} episodes, fewer than the {len(branches)} picking branches of "
            "data_dir: it must end with data_dir/success_demos's episodes"
        )
    steps = np.array([points.steps[p, c] for p, c in branches], dtype=np.int64)
    tail = lengths[len(lengths) - len(branches) :]
    if not np.array_equal(tail, steps):
        bad = int(np.flatnonzero(tail != steps)[0])
        raise ValueError(
            f"dataset_root's last {len(branches)} episodes are not data_dir's picking branches in order "
            f"(branch {bad}: {tail[bad]} frames, the branch ran {steps[bad]} steps): merge the other "
            f"episodes first and {DEMOS_DIR} last"
        )
    lead = np.zeros(len(lengths) - len(branches))
    return np.concatenate([lead, branch_advantages(points, baseline)])


def write_advantages(cfg: BranchAdvantagesConfig) -> dict:
    """Compute and write ``cfg.out`` (JSON: ``advantages`` per episode index, and their provenance)."""
    if cfg.dataset_root is None:
        raise ValueError("dataset_root is required: the LeRobotDataset the fine-tune trains on")
    points = load_points(cfg.data_dir)
    lengths = episode_lengths(cfg.dataset_root)
    advantages = dataset_advantages(points, lengths, cfg.baseline)
    n_branch = len(success_branches(points))
    branch = advantages[len(advantages) - n_branch :]
    report = {
        "advantages": [round(float(a), 6) for a in advantages],
        "data_dir": str(cfg.data_dir),
        "dataset_root": str(cfg.dataset_root),
        "baseline": cfg.baseline,
        "episodes": len(advantages),
        "branch_episodes": n_branch,
        "branch_advantage_mean": float(branch.mean()) if n_branch else 0.0,
        "branch_advantage_positive": float((branch > 0).mean()) if n_branch else 0.0,
    }
    cfg.out.parent.mkdir(parents=True, exist_ok=True)
    cfg.out.write_text(json.dumps(report, indent=1))
    return report


def load_advantages(path: str | Path, field: str = "awr_advantages_path") -> np.ndarray:
    """The per-episode advantages of a ``bboxpick-branch-advantages`` file; the error names ``field``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{field}={str(path)!r} is not a bboxpick-branch-advantages file")
    data = json.loads(path.read_text())
    if not isinstance(data, dict) or "advantages" not in data:
        raise ValueError(f"{field}={str(path)!r} holds no 'advantages' list (bboxpick-branch-advantages)")
    return np.asarray(data["advantages"], dtype=np.float32)


@draccus.wrap()
def main(cfg: BranchAdvantagesConfig) -> None:
    """Entry point of ``bboxpick-branch-advantages``."""
    logging.basicConfig(level=logging.INFO)
    report = write_advantages(cfg)
    print(
        f"{report['episodes']} episodes, {report['branch_episodes']} picking branches; branch advantage "
        f"mean {report['branch_advantage_mean']:+.3f}, positive for {report['branch_advantage_positive']:.0%}"
    )
    print(f"written: {cfg.out}")


if __name__ == "__main__":
    main()
