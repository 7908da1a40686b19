"""``bboxpick-verify-critic``: the paper's critic-verification tool (section 6.4), as a report.

    python -m lerobot_bboxpick.rl.verify --critic_path=outputs/critic/checkpoints/last/pretrained_model \
        --dataset.repo_id=local/rollouts --dataset.root=outputs/datasets/rollouts --out_dir=outputs/verify

* **Test A, value ordering**: mean V by outcome (success / miss / wrong) and phase, the 12 ordering
  checks (success > miss, success > wrong, miss > wrong in each of 4 phases), the ordering score,
  margins overall and near the terminal, and the ramp of V toward success (Spearman with progress).
* **Test B, action sensitivity**: every state's dataset chunk is swept by offsets up to +-8 cm along
  x, y and z of the **table (world) frame**, the frame the paper's sweeps and our actions live in: the
  relative chunk is made absolute with the observed TCP pose, shifted, and made relative again
  (``lerobot_bboxpick.geometry``); ``--frame=tcp`` shifts in the gripper frame instead (the paper's
  sign-flip diagnostic). Reported per axis: the mean Q range over the sweep, the across-state std of
  Q(s, a_dataset), their ratio (action/state sensitivity), the mean slope sign, and how often the
  dataset chunk is the Q-argmax among all swept candidates on pre-grasp frames of successes (a tie is
  not a win: a critic blind to actions scores 0%).

Writes ``report.md``, ``report.json`` and PNG plots into ``out_dir``.
"""

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import draccus
import numpy as np
import torch
from matplotlib.figure import Figure
from torch import Tensor

from lerobot_bboxpick.geometry import absolute_pose10, relative_pose10
from lerobot_bboxpick.rl.critic_dataset import (
    OUTCOME_GROUPS,
    PHASES,
    CriticDataConfig,
    Transitions,
    build_transitions,
    compute_embeddings,
    load_frame_table,
)
from lerobot_bboxpick.rl.diagnostics import evaluate, format_grouped, summarize

log = logging.getLogger(__name__)
AXES = ("x", "y", "z")
FRAMES = ("world", "tcp")
SPLITS = ("all", "train", "val")
# Paper table 4 (section 6.4), for the side-by-side table.
PAPER_TABLE4 = {
    "q_change": "0.01-0.03",
    "state_std": "~0.35",
    "ratio": {"x": 0.026, "y": 0.050, "z": 0.078},
    "argmax_match": "<1%",
}


@dataclass
class VerifyConfig:
    """Options of ``bboxpick-verify-critic``."""

    critic_path: Path | None = None
    dataset: CriticDataConfig = field(default_factory=CriticDataConfig)
    out_dir: Path = Path("outputs/verify_critic")
    # Which transitions: all, or the critic's training / validation episodes (same split options).
    split: str = "all"
    sweep_max_m: float = 0.08
    # Offsets per axis, symmetric around 0 (odd, so the dataset chunk itself is one of them).
    sweep_points: int = 9
    frame: str = "world"
    # Test B runs on at most this many states (a seeded sample); pre-grasp frames are always kept.
    max_states: int = 2000
    # Verdict thresholds on the action/state ratio (ours; the paper calls 0.026-0.078 "too flat").
    flat_ratio: float = 0.1
    sensitive_ratio: float = 0.5
    embed_batch_size: int = 32
    seed: int = 0
    progress: bool = True

    def __post_init__(self) -> None:
        self.out_dir = Path(self.out_dir)
        self.critic_path = Path(self.critic_path) if self.critic_path is not None else None
        if self.split not in SPLITS:
            raise ValueError(f"split={self.split!r} is not one of {', '.join(SPLITS)}")
        if self.frame not in FRAMES:
            raise ValueError(f"frame={self.frame!r} is not one of {', '.join(FRAMES)}")
        if self.sweep_points < 3 or self.sweep_points % 2 == 0:
            raise ValueError(f"sweep_points={self.sweep_points} must be odd and >= 3 (0 is one of them)")
        if not self.sweep_max_m > 0:
            raise ValueError(f"sweep_max_m={self.sweep_max_m} must be > 0")
        if self.max_states < 2:
            raise ValueError(f"max_states={self.max_states} must be >= 2")


# --------------------------------------------------------------------------- test B maths
def sweep_offsets(max_offset: float, points: int) -> np.ndarray:
    """``points`` offsets evenly spaced in ``[-max_offset, max_offset]`` (0 in the middle)."""
    return np.linspace(-max_offset, max_offset, points)


def shift_chunks(
    relative: np.ndarray, base: np.ndarray, offset: np.ndarray, frame: str = "world"
) -> np.ndarray:
    """Translate every pose of relative chunks ``(N, H, 10)`` by ``offset`` (3,) metres.

    ``world``: in the table frame (absolute chunk = base pose composed with the relative one, shifted,
    made relative again); ``tcp``: in the frame of the observed TCP pose the chunk is relative to.
    """
    if frame not in FRAMES:
        raise ValueError(f"frame={frame!r} is not one of {', '.join(FRAMES)}")
    offset = np.asarray(offset, dtype=np.float64).reshape(3)
    if frame == "tcp":
        out = np.array(relative, dtype=np.float64, copy=True)
        out[..., :3] += offset
        return out
    absolute = absolute_pose10(relative, base[:, None, :])
    absolute[..., :3] += offset
    return relative_pose10(absolute, base[:, None, :])


@torch.no_grad()
def _q_of(model, states: Tensor, chunks: np.ndarray, batch_size: int = 1024) -> np.ndarray:
    out = [
        model.q(states[i : i + batch_size], torch.from_numpy(chunks[i : i + batch_size]).float())
        for i in range(0, len(states), batch_size)
    ]
    return torch.cat(out).float().numpy()


def action_sensitivity(
    model, embeddings: Tensor, tr: Transitions, offsets: np.ndarray, frame: str = "world"
) -> dict:
    """Test B on transitions ``tr`` (see the module docstring); ``model`` needs ``q(state, chunk)``.

    Returns per axis: ``q_curve`` (mean Q(s, a + d) - Q(s, a) per offset), ``q_change`` (mean over
    states of the Q range over the sweep), ``q_change_at_max`` (mean |Q(a +- max) - Q(a)|), ``slope``
    (mean (Q(a + max) - Q(a - max)) / (2 max), per metre), ``ratio`` (q_change / state_std); and
    ``state_std`` (std over states of Q(s, a_dataset)) and the pre-grasp ``argmax_match`` rate.
    """
    offsets = np.asarray(offsets, dtype=np.float64)
    zero = int(np.flatnonzero(np.isclose(offsets, 0.0))[0]) if np.any(np.isclose(offsets, 0.0)) else None
    if zero is None:
        raise ValueError("the sweep offsets must include 0 (the dataset chunk)")
    states = embeddings[torch.from_numpy(tr.obs_row)]
    q_data = _q_of(model, states, tr.actions)
    state_std = float(q_data.std()) if len(q_data) > 1 else 0.0
    per_axis: dict[str, dict] = {}
    swept: list[np.ndarray] = []  # (N,) Q per non-zero candidate, all axes
    for k, axis in enumerate(AXES):
        qs = np.empty((len(tr), len(offsets)))
        for j, d in enumerate(offsets):
            if j == zero:
                qs[:, j] = q_data
                continue
            vec = np.zeros(3)
            vec[k] = d
            qs[:, j] = _q_of(
                model, states, shift_chunks(tr.actions, tr.base_pose, vec, frame).astype(np.float32)
            )
            swept.append(qs[:, j])
        q_range = qs.max(1) - qs.min(1)
        change = float(q_range.mean())
        per_axis[axis] = {
            "q_curve": (qs - q_data[:, None]).mean(0).tolist(),
            "q_curve_std": (qs - q_data[:, None]).std(0).tolist(),
            "q_change": change,
            "q_change_at_max": float(np.abs(qs[:, [0, -1]] - q_data[:, None]).mean()),
            "slope": float(((qs[:, -1] - qs[:, 0]) / (offsets[-1] - offsets[0])).mean()),
            "ratio": change / state_std if state_std > 0 else (0.0 if change == 0 else float("inf")),
        }
    pre = tr.pregrasp
    match = None
    if pre.any():
        others = np.stack(swept, axis=1)[pre]
        match = float(np.mean(q_data[pre] > others.max(1)))  # strictly best: ties are no win
    return {
        "frame": frame,
        "offsets": offsets.tolist(),
        "n_states": len(tr),
        "state_std": state_std,
        "axes": per_axis,
        "argmax_match": match,
        "n_pregrasp": int(pre.sum()),
    }


def verdict(ratio: float, flat: float, sensitive: float) -> str:
    """Words for an action/state ratio."""
    if ratio < flat:
        return "too flat"
    return "weak" if ratio < sensitive else "action-sensitive"


# --------------------------------------------------------------------------- report
def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f}%"


def _num(x: float | None, fmt: str = "{:.3f}") -> str:
    return "-" if x is None else fmt.format(x)


def sensitivity_table(b: dict, cfg: VerifyConfig) -> str:
    """Markdown: our test-B numbers beside the paper's table 4."""
    cm = f"+-{100 * cfg.sweep_max_m:g} cm"
    ax = b["axes"]
    rows = [
        "| diagnostic | dx | dy | dz | paper (dx / dy / dz) |",
        "|---|---|---|---|---|",
        f"| Q change under {cm} sweep (mean range) | "
        + " | ".join(_num(ax[a]["q_change"]) for a in AXES)
        + f" | {PAPER_TABLE4['q_change']} |",
        "| mean abs Q change at the sweep ends | "
        + " | ".join(_num(ax[a]["q_change_at_max"]) for a in AXES)
        + " | - |",
        "| mean slope dQ/d(offset) (per m) | "
        + " | ".join(_num(ax[a]["slope"], "{:+.3f}") for a in AXES)
        + " | - |",
        f"| across-state Q std | {_num(b['state_std'])} | | | {PAPER_TABLE4['state_std']} |",
        "| action/state sensitivity ratio | "
        + " | ".join(_num(ax[a]["ratio"]) for a in AXES)
        + " | "
        + " / ".join(f"{PAPER_TABLE4['ratio'][a]:.3f}" for a in AXES)
        + " |",
        "| verdict | "
        + " | ".join(verdict(ax[a]["ratio"], cfg.flat_ratio, cfg.sensitive_ratio) for a in AXES)
        + " | too flat / too flat / too flat |",
        f"| dataset chunk is the Q-argmax (pre-grasp, {b['n_pregrasp']} frames) | {_pct(b['argmax_match'])} "
        f"| | | {PAPER_TABLE4['argmax_match']} |",
    ]
    return "\n".join(rows)


def render_report(a: dict, b: dict, cfg: VerifyConfig, source: str) -> str:
    """The markdown report."""
    checks = "\n".join(
        f"| {c['phase']} | {c['higher']} > {c['lower']} | {c['margin']:+.3f} | {'yes' if c['ok'] else 'NO'} |"
        for c in a["checks"]
    )
    margins = "\n".join(
        f"| {pair} | {_num(m['all'], '{:+.3f}')} | {_num(m['near_terminal'], '{:+.3f}')} | "
        f"{_num(m['terminal'], '{:+.3f}')} |"
        for pair, m in a["margins"].items()
    )
    ramps = "\n".join(
        f"| {g} | {a['ramp_v'][g]['n']} | {_num(a['ramp_v'][g]['spearman'], '{:+.2f}')} | "
        f"{_num(a['ramp_q'][g]['spearman'], '{:+.2f}')} |"
        for g in OUTCOME_GROUPS
        if a["ramp_v"][g]["n"]
    )
    score = a["ordering_score"]
    return f"""# Critic verification

Critic `{cfg.critic_path}` on {source}, split `{cfg.split}`: {a["n"]} transitions.

## Test A: value ordering and temporal ramp

Ordering score **{_num(score, "{:.2f}")}** over {len(a["checks"])} checks (paper: 1.00 over 12).

Mean V by outcome and phase:

{format_grouped(a, "v")}

Mean Q (dataset chunks):

{format_grouped(a, "q")}

| phase | check | margin | holds |
|---|---|---|---|
{checks}

Margins of mean V (paper: success-miss +0.62, success-wrong +0.88 overall, about +1.0 near terminal):

| pair | overall | near terminal | terminal |
|---|---|---|---|
{margins}

Ramp toward the end of the episode (Spearman of V and Q with progress; success should be > 0):

| outcome | transitions | V | Q |
|---|---|---|---|
{ramps}

![V by outcome and phase](value_by_outcome_phase.png)
![ramp](ramp.png)

## Test B: action sensitivity ({b["frame"]} frame, {b["n_states"]} states)

{sensitivity_table(b, cfg)}

![sweeps](sweeps.png)

Ratio = mean Q range over the sweep / across-state std of Q(s, a_dataset). Verdicts: < {cfg.flat_ratio:g}
too flat, < {cfg.sensitive_ratio:g} weak, else action-sensitive.
"""


def plot_values(a: dict, path: Path) -> None:
    """Bars of mean V per phase, one group of bars per outcome."""
    fig = Figure(figsize=(7, 3.5))
    ax = fig.subplots()
    width = 0.8 / len(OUTCOME_GROUPS)
    for i, g in enumerate(OUTCOME_GROUPS):
        vals = [a["grouped"]["v"][g][p] for p in PHASES]
        ax.bar(np.arange(len(PHASES)) + i * width, [np.nan if v is None else v for v in vals], width, label=g)
    ax.set_xticks(np.arange(len(PHASES)) + width, PHASES)
    ax.set_ylabel("mean V")
    ax.axhline(0, color="k", lw=0.5)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def plot_ramp(a: dict, path: Path) -> None:
    """Mean V per progress bin, per outcome."""
    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    for g in OUTCOME_GROUPS:
        r = a["ramp_v"][g]
        if r["n"]:
            ax.plot(r["bin_centres"], [np.nan if m is None else m for m in r["means"]], "o-", label=g)
    ax.set_xlabel("progress to the terminal frame")
    ax.set_ylabel("mean V")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def plot_sweeps(b: dict, path: Path) -> None:
    """Mean Q(s, a + d) - Q(s, a) per offset and axis, with the across-state std for scale."""
    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    d = 100 * np.asarray(b["offsets"])
    for axis in AXES:
        m, s = np.asarray(b["axes"][axis]["q_curve"]), np.asarray(b["axes"][axis]["q_curve_std"])
        ax.plot(d, m, "o-", label=f"d{axis}")
        ax.fill_between(d, m - s, m + s, alpha=0.15)
    for sign in (1, -1):
        ax.axhline(sign * b["state_std"], color="k", ls="--", lw=0.8)
    ax.set_xlabel(f"offset of the chunk's positions ({b['frame']} frame), cm")
    ax.set_ylabel("Q(s, a + d) - Q(s, a)")
    ax.set_title("dashed: +- across-state std of Q")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def write_report(a: dict, b: dict, cfg: VerifyConfig, source: str) -> Path:
    """``report.md``, ``report.json`` and the plots in ``cfg.out_dir``; returns the markdown path."""
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    plot_values(a, cfg.out_dir / "value_by_outcome_phase.png")
    plot_ramp(a, cfg.out_dir / "ramp.png")
    plot_sweeps(b, cfg.out_dir / "sweeps.png")
    (cfg.out_dir / "report.json").write_text(json.dumps({"test_a": a, "test_b": b}, indent=1))
    md = cfg.out_dir / "report.md"
    md.write_text(render_report(a, b, cfg, source))
    return md


def _sample_for_b(tr: Transitions, max_states: int, seed: int) -> Transitions:
    if len(tr) <= max_states:
        return tr
    rng = np.random.default_rng(seed)
    keep = tr.pregrasp.copy()
    rest = np.flatnonzero(~keep)
    n = max(0, max_states - int(keep.sum()))
    keep[rng.choice(rest, size=min(n, len(rest)), replace=False)] = True
    return tr.subset(keep)


def verify_critic(cfg: VerifyConfig) -> dict:
    """Run tests A and B on a dataset and write the report; returns ``{"test_a", "test_b", "report"}``."""
    if cfg.critic_path is None:
        raise ValueError(
            "critic_path is required: a folder written by bboxpick-train-critic (.../pretrained_model)"
        )
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel

    model = IqlCriticModel.from_pretrained(cfg.critic_path)
    pc = model.encoder.config
    dataset = LeRobotDataset(cfg.dataset.repo_id, root=cfg.dataset.root)
    table = load_frame_table(dataset)
    stride = cfg.dataset.chunk_stride or pc.n_action_steps
    tr = build_transitions(table, cfg.dataset, pc.horizon, stride, model.config.gamma)
    if cfg.split != "all":
        tr = tr.subset(tr.is_val if cfg.split == "val" else ~tr.is_val)
    if len(tr) < 2:
        raise ValueError(f"split={cfg.split!r} leaves {len(tr)} transitions; need at least 2")
    embeddings = compute_embeddings(
        model.encode, dataset, table, pc.n_obs_steps, cfg.embed_batch_size, cfg.progress
    )
    a = summarize(evaluate(model, embeddings, tr), tr)
    offsets = sweep_offsets(cfg.sweep_max_m, cfg.sweep_points)
    b = action_sensitivity(model, embeddings, _sample_for_b(tr, cfg.max_states, cfg.seed), offsets, cfg.frame)
    md = write_report(a, b, cfg, f"dataset `{cfg.dataset.repo_id}` ({cfg.dataset.root})")
    return {"test_a": a, "test_b": b, "report": str(md)}


@draccus.wrap()
def main(cfg: VerifyConfig) -> None:
    """Entry point of ``bboxpick-verify-critic``."""
    logging.basicConfig(level=logging.INFO)
    result = verify_critic(cfg)
    b = result["test_b"]
    print(f"report: {result['report']}")
    print(f"test A ordering score: {result['test_a']['ordering_score']}")
    print("test B ratios: " + ", ".join(f"d{a}={b['axes'][a]['ratio']:.3f}" for a in AXES))


if __name__ == "__main__":
    main()
