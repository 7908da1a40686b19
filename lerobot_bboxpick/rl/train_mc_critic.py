"""``bboxpick-train-mc-critic``: a critic regressed on Monte-Carlo returns of counterfactual branches.

    bboxpick-train-mc-critic --data_dir=outputs/counterfactual --output_dir=outputs/mc_critic

Same model as the IQL critic (``IqlCriticModel``: the policy's frozen encoder, twin Q over the
16 x 10 relative chunk, V), so it saves, loads, reranks (``bboxpick-suite --critic_path``) and verifies
(``bboxpick-verify-critic``) the same way; only the targets differ. ``bboxpick-counterfactual`` tried
several chunks from each saved state and followed each to its outcome, so every (state, chunk) pair has
a true return: both Q heads regress it (mean squared error), and V regresses the mean return of the
policy's own draws there (``policy`` and ``sampleK`` candidates: a Monte-Carlo estimate of V^pi).
No bootstrapping, so no overestimation to guard against; the price is that Q is the value of the
chunk *followed by the data's policy*, which is what reranking that policy's proposals needs.

Branch points are split by episode (``val_fraction`` of the episodes, seeded) and the report written
beside the checkpoint (``mc_report.json``/``.md``) compares, on the held-out points, the chunk the
critic ranks first with the policy's own chunk and with the best candidate, and runs the paper's test B
(``verify.action_sensitivity``) next to the *true* sensitivity the branches measured.
"""

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import draccus
import numpy as np
import torch
from torch import Tensor
from tqdm import tqdm

from lerobot_bboxpick.geometry import relative_pose10
from lerobot_bboxpick.keys import BBOX, STATE, WRIST_IMAGE
from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.counterfactual_dataset import CONFIG_NAME, CounterfactualPoints, load_points
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel, load_policy
from lerobot_bboxpick.rl.sign_flip import sign_agreement, sign_flip_table
from lerobot_bboxpick.rl.train_critic import prepare_output_dir, save_critic_checkpoint
from lerobot_bboxpick.sim.outcome import OUTCOMES

log = logging.getLogger(__name__)
REPORT_NAME = "mc_report"


@dataclass
class TrainMcCriticConfig:
    """Options of ``bboxpick-train-mc-critic``."""

    # A bboxpick-counterfactual output folder.
    data_dir: Path = Path("outputs/counterfactual")
    # The bbox_diffusion checkpoint whose encoder the critic reuses (None: the one the branches ran).
    policy_path: Path | None = None
    critic: IqlCriticConfig = field(default_factory=IqlCriticConfig)
    output_dir: Path = Path("outputs/mc_critic")
    overwrite: bool = False
    steps: int = 3000
    batch_size: int = 256
    lr: float = 4e-4
    weight_decay: float = 1e-4
    warmup_steps: int = 150
    val_fraction: float = 0.2
    # Another critic checkpoint (e.g. bboxpick-train-critic's IQL one) evaluated on the same held-out
    # points, side by side in the report.
    compare_critic_path: Path | None = None
    seed: int = 0
    embed_batch_size: int = 32
    progress: bool = True

    def __post_init__(self) -> None:
        self.data_dir, self.output_dir = Path(self.data_dir), Path(self.output_dir)
        self.policy_path = Path(self.policy_path) if self.policy_path is not None else None
        if self.compare_critic_path is not None:
            self.compare_critic_path = Path(self.compare_critic_path)
        for name in ("steps", "batch_size", "embed_batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 1")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction={self.val_fraction} must be in [0, 1)")
        if not self.critic.freeze_encoder:
            raise ValueError(
                "critic.freeze_encoder=false is not supported here: the encoder stays the policy's"
            )


def policy_columns(kinds: list[str]) -> np.ndarray:
    """Indices of the candidates the policy itself drew (``policy``, ``sampleK``)."""
    return np.array([i for i, k in enumerate(kinds) if k == "policy" or k.startswith("sample")])


def split_by_episode(points: CounterfactualPoints, fraction: float, seed: int) -> np.ndarray:
    """Held-out mask over points: every point of ``round(fraction * episodes)`` episodes."""
    episodes = sorted(
        {(s, int(x)) for s, x in zip(points.setting.tolist(), points.seed.tolist(), strict=True)}
    )
    rng = np.random.default_rng(seed)
    n_val = int(math.floor(fraction * len(episodes) + 0.5))
    chosen = {episodes[i] for i in rng.permutation(len(episodes))[:n_val]}
    return np.array(
        [(s, int(x)) in chosen for s, x in zip(points.setting.tolist(), points.seed.tolist(), strict=True)]
    )


def relative_candidates(points: CounterfactualPoints) -> np.ndarray:
    """(P, C, H, 10) candidates relative to each point's observed TCP pose (the critic's action space)."""
    return relative_pose10(points.candidates.astype(np.float64), points.base_pose[:, None, None, :]).astype(
        np.float32
    )


@torch.no_grad()
def point_features(
    model: IqlCriticModel, points: CounterfactualPoints, batch_size: int, progress: bool
) -> Tensor:
    """State features (P, D) of every branch point, through the policy's encoder."""
    out = []
    for i in tqdm(range(0, len(points), batch_size), desc="encoding points", disable=not progress):
        sl = slice(i, i + batch_size)
        batch = {
            WRIST_IMAGE: torch.from_numpy(points.image[sl]).float() / 255,
            STATE: torch.from_numpy(points.state[sl]).float(),
            BBOX: torch.from_numpy(points.bbox[sl]).float(),
        }
        out.append(model.encode(batch).float())
    return torch.cat(out)


@torch.no_grad()
def q_table(model: IqlCriticModel, feats: Tensor, rel: np.ndarray) -> np.ndarray:
    """(P, C) Q of every candidate."""
    p, c = rel.shape[:2]
    q = model.q(feats.repeat_interleave(c, dim=0), torch.from_numpy(rel.reshape(p * c, *rel.shape[2:])))
    return q.view(p, c).numpy()


def rerank_evaluation(q: np.ndarray, points: CounterfactualPoints) -> dict:
    """How the argmax-Q candidate does against the policy's own chunk and the best candidate, over all
    candidates and over the policy's draws only (the reranker's trust region)."""
    pick = points.outcome == OUTCOMES.index("pick")
    wrong = points.outcome == OUTCOMES.index("wrong")
    rows = np.arange(len(points))
    out = {
        "points": len(points),
        "policy_pick": float(pick[:, 0].mean()),
        "policy_wrong": float(wrong[:, 0].mean()),
    }
    for name, cols in (
        ("all", np.arange(points.candidates.shape[1])),
        ("policy_draws", policy_columns(points.kinds)),
    ):
        chosen = cols[q[:, cols].argmax(1)]
        out[name] = {
            "candidates": len(cols),
            "chosen_pick": float(pick[rows, chosen].mean()),
            "chosen_wrong": float(wrong[rows, chosen].mean()),
            "best_possible_pick": float(pick[:, cols].any(1).mean()),
            "mean_candidate_pick": float(pick[:, cols].mean()),
        }
    return out


def true_sensitivity(points: CounterfactualPoints) -> dict:
    """Per axis with +/- perturbations: mean return range over {-d, policy, +d} and its ratio to the
    across-state std of the policy chunk's return (test B's ratio, measured instead of predicted)."""
    std = float(points.ret[:, 0].std())
    out = {"state_std": std, "axes": {}}
    for axis in ("x", "y", "z", "yaw", "gripper"):
        plus = [i for i, k in enumerate(points.kinds) if k.startswith(axis + "+")]
        minus = [i for i, k in enumerate(points.kinds) if k.startswith(axis + "-")]
        if not plus or not minus:
            continue
        trio = points.ret[:, [minus[0], 0, plus[0]]]
        change = float((trio.max(1) - trio.min(1)).mean())
        out["axes"][axis] = {
            "amount": points.kinds[plus[0]][len(axis) :],
            "ret_change": change,
            "ratio": change / std if std > 0 else 0.0,
        }
    return out


@dataclass
class SweepStates:
    """What ``verify.action_sensitivity`` reads: branch points as 'transitions' with the policy's chunk."""

    obs_row: np.ndarray
    actions: np.ndarray
    base_pose: np.ndarray
    pregrasp: np.ndarray

    def __len__(self) -> int:
        return len(self.obs_row)


def sweep_states(points: CounterfactualPoints, rel: np.ndarray) -> SweepStates:
    """Every point, its policy chunk as the 'dataset' chunk; pre-grasp = the policy chunk keeps the
    gripper open (width above half of its start)."""
    width = points.candidates[:, 0, :, 9]
    return SweepStates(
        obs_row=np.arange(len(points)),
        actions=rel[:, 0],
        base_pose=points.base_pose,
        pregrasp=width.min(1) > 0.5 * points.state[:, -1, 9],
    )


def _fit(
    cfg: TrainMcCriticConfig,
    model: IqlCriticModel,
    feats: Tensor,
    rel: np.ndarray,
    points: CounterfactualPoints,
    train_rows: np.ndarray,
) -> list[dict]:
    from diffusers.optimization import get_cosine_schedule_with_warmup

    pc = policy_columns(points.kinds)
    c = rel.shape[1]
    pairs = np.stack(np.meshgrid(train_rows, np.arange(c), indexing="ij"), -1).reshape(-1, 2)
    v_target = torch.from_numpy(points.ret[:, pc].mean(1)).float()
    ret = torch.from_numpy(points.ret).float()
    rel_t = torch.from_numpy(rel)
    optimizer = torch.optim.AdamW(model.get_optim_params(cfg.lr, 0.0), weight_decay=cfg.weight_decay)
    scheduler = get_cosine_schedule_with_warmup(optimizer, min(cfg.warmup_steps, cfg.steps), cfg.steps)
    rng = np.random.default_rng(cfg.seed)
    history = []
    model.train()
    bar = tqdm(total=cfg.steps, desc="mc critic", unit="step", disable=not cfg.progress)
    for step in range(cfg.steps):
        idx = pairs[rng.integers(len(pairs), size=cfg.batch_size)]
        p, k = torch.from_numpy(idx[:, 0]), torch.from_numpy(idx[:, 1])
        s = feats[p]
        q1, q2 = model.critic.q(s, model.flat_actions(rel_t[p, k]))
        y = ret[p, k]
        l_q = (q1 - y).square().mean() + (q2 - y).square().mean()
        l_v = (model.critic.v(s) - v_target[p]).square().mean()
        loss = l_q + l_v
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        scheduler.step()
        bar.update()
        if step % 100 == 0 or step == cfg.steps - 1:
            history.append({"step": step, "q_loss": l_q.item() / 2, "v_loss": l_v.item()})
            bar.set_postfix(q_loss=f"{l_q.item() / 2:.4f}")
    bar.close()
    model.eval()
    return history


def evaluate_critic(
    model: IqlCriticModel, points: CounterfactualPoints, rel: np.ndarray, feats: Tensor | None = None
) -> dict:
    """Reranking, sign agreement and test B of ``model`` on ``points`` (features computed unless given)."""
    from lerobot_bboxpick.rl.verify import action_sensitivity, sweep_offsets

    if feats is None:
        feats = point_features(model, points, 32, progress=False)
    q = q_table(model, feats, rel)
    return {
        "rerank": rerank_evaluation(q, points),
        "sign_flip": sign_agreement(q, points.ret, points.kinds, points.base_pose),
        "test_b": action_sensitivity(model, feats, sweep_states(points, rel), sweep_offsets(0.08, 9)),
    }


def comparison_table(report: dict) -> str:
    """Markdown: test B and reranking of the MC critic, the compared critic and the paper's table 4."""
    from lerobot_bboxpick.rl.verify import PAPER_TABLE4

    cols = [("MC critic (counterfactual)", report["val"])]
    if "compare" in report:
        cols.append((f"compared: `{report['compare']['path']}`", report["compare"]))
    lines = [
        _row("held-out points", *(name for name, _ in cols), "paper table 4"),
        "|---|" + "---|" * (len(cols) + 1),
    ]
    for axis in ("x", "y", "z"):
        lines.append(
            _row(
                f"test B ratio {axis}",
                *(f"{c['test_b']['axes'][axis]['ratio']:.2f}" for _, c in cols),
                PAPER_TABLE4["ratio"][axis],
            )
        )
        lines.append(
            _row(
                f"Q change, +-8 cm {axis}",
                *(f"{c['test_b']['axes'][axis]['q_change']:.3f}" for _, c in cols),
                PAPER_TABLE4["q_change"],
            )
        )
    lines.append(
        _row(
            "across-state Q std",
            *(f"{c['test_b']['state_std']:.3f}" for _, c in cols),
            PAPER_TABLE4["state_std"],
        )
    )
    lines.append(
        _row(
            "argmax-Q of all candidates picks",
            *(f"{c['rerank']['all']['chosen_pick']:.0%}" for _, c in cols),
            "-",
        )
    )
    lines.append(
        _row(
            "argmax-Q of the policy's draws picks",
            *(f"{c['rerank']['policy_draws']['chosen_pick']:.0%}" for _, c in cols),
            "-",
        )
    )
    return "\n".join(lines) + "\n"


def _row(*cells: object) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def markdown_report(report: dict) -> str:
    """The report as markdown."""
    lines = [
        "# Monte-Carlo critic on counterfactual branches\n",
        f"Data: `{report['data_dir']}`, {report['points']} branch points ({report['train_points']} train / "
        f"{report['val_points']} held out, split by episode), {len(report['kinds'])} candidates each: "
        f"{', '.join(report['kinds'])}.\n",
        "## Reranking on held-out points\n",
        _row("choice set", "candidates", "argmax-Q picks", "argmax-Q wrong", "policy's chunk picks")
        + " best candidate picks | mean candidate picks |",
        "|---|---|---|---|---|---|---|",
    ]
    r = report["val"]["rerank"]
    for name in ("policy_draws", "all"):
        x = r[name]
        lines.append(
            _row(
                name,
                x["candidates"],
                f"{x['chosen_pick']:.0%}",
                f"{x['chosen_wrong']:.0%}",
                f"{r['policy_pick']:.0%}",
                f"{x['best_possible_pick']:.0%}",
                f"{x['mean_candidate_pick']:.0%}",
            )
        )
    lines += [
        "\n## Action sensitivity (held-out points)\n",
        _row("axis", "true return change (branches)", "true ratio", "critic Q change (+-8 cm, test B)")
        + " critic ratio |",
        "|---|---|---|---|---|",
    ]
    t, b = report["true_sensitivity"], report["val"]["test_b"]
    for axis, ta in t["axes"].items():
        ba = b["axes"].get(axis)
        lines.append(
            _row(
                axis,
                f"{ta['ret_change']:.3f} (+-{ta['amount'].lstrip('+')})",
                f"{ta['ratio']:.2f}",
                "-" if ba is None else f"{ba['q_change']:.3f}",
                "-" if ba is None else f"{ba['ratio']:.2f}",
            )
        )
    match = "n/a" if b["argmax_match"] is None else format(b["argmax_match"], ".0%")
    lines.append(
        f"\nAcross-state std: returns {t['state_std']:.3f}, critic Q {b['state_std']:.3f}. "
        f"The policy's chunk is "
        f"strictly the Q-argmax of its sweep on {match} of {b['n_pregrasp']} pre-grasp points."
    )
    lines += ["\n## Side by side\n", comparison_table(report)]
    columns = [("MC", report["val"]["sign_flip"])]
    if "compare" in report:
        columns.append(("compared", report["compare"]["sign_flip"]))
    lines += [
        "\n## Sign flips (held-out points)\n",
        "Where the +d and -d branches' true returns differ: how often each critic prefers the better "
        "sign (50% = chance), how often the TCP's own axis points against the world's (a residual grid "
        "built in the TCP frame would move the other way there), and the critic's agreement if its "
        "choice were read in the TCP frame (`lerobot_bboxpick.rl.sign_flip`).\n",
        sign_flip_table(columns),
    ]
    return "\n".join(lines) + "\n"


def train_mc_critic(cfg: TrainMcCriticConfig) -> dict:
    """Train, save like ``bboxpick-train-critic`` does, evaluate; returns the report dict."""
    prepare_output_dir(cfg.output_dir, cfg.overwrite)
    policy_path = cfg.policy_path
    if policy_path is None:
        meta = json.loads((cfg.data_dir / CONFIG_NAME).read_text())
        policy_path = Path(meta["config"]["policy_path"])
    points = load_points(cfg.data_dir)
    with torch.random.fork_rng():
        torch.manual_seed(cfg.seed)
        model = IqlCriticModel.from_policy(cfg.critic, load_policy(policy_path))
        rel = relative_candidates(points)
        feats = point_features(model, points, cfg.embed_batch_size, cfg.progress)
        is_val = split_by_episode(points, cfg.val_fraction, cfg.seed)
        train_rows = np.flatnonzero(~is_val)
        if len(train_rows) == 0:
            raise ValueError("no training points: every episode is held out")
        history = _fit(cfg, model, feats, rel, points, train_rows)
    val = points.subset(is_val) if is_val.any() else points
    val_rows = np.flatnonzero(is_val) if is_val.any() else np.arange(len(points))
    report = {
        "data_dir": str(cfg.data_dir),
        "policy_path": str(policy_path),
        "points": len(points),
        "train_points": int(len(train_rows)),
        "val_points": int(is_val.sum()),
        "kinds": points.kinds,
        "val": evaluate_critic(model, val, rel[val_rows], feats[val_rows]),
        "train_rerank": rerank_evaluation(
            q_table(model, feats[train_rows], rel[train_rows]), points.subset(~is_val)
        ),
        "true_sensitivity": true_sensitivity(val),
        "history": history,
    }
    if cfg.compare_critic_path is not None:
        other = IqlCriticModel.from_pretrained(cfg.compare_critic_path)
        report["compare"] = {
            "path": str(cfg.compare_critic_path),
            **evaluate_critic(other, val, rel[val_rows]),
        }
    pretrained = save_critic_checkpoint(model, cfg, cfg.output_dir, cfg.steps, cfg.steps)
    report["checkpoint"] = str(pretrained)
    (cfg.output_dir / f"{REPORT_NAME}.json").write_text(json.dumps(report, indent=1))
    (cfg.output_dir / f"{REPORT_NAME}.md").write_text(markdown_report(report))
    return report


@draccus.wrap()
def main(cfg: TrainMcCriticConfig) -> None:
    """Entry point of ``bboxpick-train-mc-critic``."""
    logging.basicConfig(level=logging.INFO)
    report = train_mc_critic(cfg)
    print(markdown_report(report))
    print(f"checkpoint: {report['checkpoint']}")


if __name__ == "__main__":
    main()
