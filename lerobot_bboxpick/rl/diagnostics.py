"""Critic diagnostics (paper sections 5.3 and 6.4, test A): V / Q / A / TD grouped by outcome and phase,
the value-ordering checks (success > miss > wrong in every phase), margins, and the ramp toward success.

Everything here works on numbers already computed (``evaluate``), so training and ``verify`` share it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import spearmanr
from torch import Tensor

from lerobot_bboxpick.rl.critic_dataset import OUTCOME_GROUPS, PHASES, Transitions

ORDER_PAIRS: tuple[tuple[str, str], ...] = (("success", "miss"), ("success", "wrong"), ("miss", "wrong"))
METRICS = ("v", "q", "adv", "td")


@dataclass
class CriticValues:
    """Per-transition critic outputs (numpy, aligned with a ``Transitions``)."""

    v: np.ndarray
    q: np.ndarray
    adv: np.ndarray  # Q - V
    td: np.ndarray  # Q - (r + discount * (1 - done) * V(s'))


@torch.no_grad()
def evaluate(model, embeddings: Tensor, tr: Transitions, batch_size: int = 1024) -> CriticValues:
    """V, Q (min of the online twins), advantage and TD error of every transition.

    ``model`` needs ``v(state)`` and ``q(state, relative_chunk)``; ``embeddings`` are its state features
    of every frame row.
    """
    out: dict[str, list[np.ndarray]] = {k: [] for k in METRICS}
    for i in range(0, len(tr), batch_size):
        sl = slice(i, i + batch_size)
        s = embeddings[torch.from_numpy(tr.obs_row[sl])]
        s_next = embeddings[torch.from_numpy(tr.next_row[sl])]
        a = torch.from_numpy(tr.actions[sl])
        v, q, v_next = model.v(s), model.q(s, a), model.v(s_next)
        target = (
            torch.from_numpy(tr.reward[sl])
            + torch.from_numpy(tr.discount[sl]) * (1.0 - torch.from_numpy(tr.done[sl]).float()) * v_next
        )
        for k, x in zip(METRICS, (v, q, q - v, q - target), strict=True):
            out[k].append(x.float().cpu().numpy())
    return CriticValues(**{k: np.concatenate(v) if v else np.zeros(0) for k, v in out.items()})


def grouped(values: CriticValues, tr: Transitions) -> dict[str, dict[str, dict[str, float | None]]]:
    """``{metric: {group: {phase or "all": mean}}}``; None where a bucket is empty. Also ``count``."""
    out: dict[str, dict[str, dict[str, float | None]]] = {}
    for metric in (*METRICS, "count"):
        table: dict[str, dict[str, float | None]] = {}
        for gi, g in enumerate(OUTCOME_GROUPS):
            row: dict[str, float | None] = {}
            for name, mask in [("all", tr.group == gi)] + [
                (p, (tr.group == gi) & (tr.phase == pi)) for pi, p in enumerate(PHASES)
            ]:
                if metric == "count":
                    row[name] = float(mask.sum())
                else:
                    x = getattr(values, metric)[mask]
                    row[name] = float(x.mean()) if len(x) else None
            table[g] = row
        out[metric] = table
    return out


def ordering_checks(v_table: dict[str, dict[str, float | None]]) -> list[dict]:
    """One check per phase and ordered pair (4 x 3 = 12 when every bucket has data): is mean V higher
    for the better outcome? Empty buckets give no check."""
    checks = []
    for phase in PHASES:
        for hi, lo in ORDER_PAIRS:
            a, b = v_table[hi][phase], v_table[lo][phase]
            if a is None or b is None:
                continue
            checks.append({"phase": phase, "higher": hi, "lower": lo, "margin": a - b, "ok": bool(a > b)})
    return checks


def margin(v_table: dict[str, dict[str, float | None]], hi: str, lo: str, phase: str) -> float | None:
    """Mean V of ``hi`` minus that of ``lo`` in ``phase`` (or "all"); None if either is empty."""
    a, b = v_table[hi][phase], v_table[lo][phase]
    return None if a is None or b is None else a - b


def ramp(values: np.ndarray, tr: Transitions, group: str = "success", bins: int = 10) -> dict:
    """Mean of ``values`` per progress bin for one outcome group and their Spearman correlation with
    progress (a value that ramps up toward a successful grasp has a correlation near +1)."""
    mask = tr.group == OUTCOME_GROUPS.index(group)
    x, p = values[mask], tr.progress[mask]
    edges = np.linspace(0, 1, bins + 1)
    which = np.clip(np.digitize(p, edges) - 1, 0, bins - 1)
    means = [float(x[which == k].mean()) if np.any(which == k) else None for k in range(bins)]
    rho = float(spearmanr(p, x).statistic) if len(x) > 2 and np.ptp(x) > 0 else None
    return {
        "bin_centres": ((edges[:-1] + edges[1:]) / 2).tolist(),
        "means": means,
        "spearman": rho,
        "n": int(mask.sum()),
    }


def summarize(values: CriticValues, tr: Transitions) -> dict:
    """Test A in numbers: grouped tables, ordering checks and score, margins, ramps (JSON-able)."""
    table = grouped(values, tr)
    checks = ordering_checks(table["v"])
    return {
        "n": len(tr),
        "grouped": table,
        "checks": checks,
        "ordering_score": float(np.mean([c["ok"] for c in checks])) if checks else None,
        "margins": {
            f"{hi}-{lo}": {p: margin(table["v"], hi, lo, p) for p in ("all", "near_terminal", "terminal")}
            for hi, lo in ORDER_PAIRS
        },
        "ramp_v": {g: ramp(values.v, tr, g) for g in OUTCOME_GROUPS},
        "ramp_q": {g: ramp(values.q, tr, g) for g in OUTCOME_GROUPS},
    }


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:+.3f}"


def format_grouped(summary: dict, metric: str = "v") -> str:
    """A markdown table of one metric by outcome group (rows) and phase (columns)."""
    cols = ("all", *PHASES)
    lines = [f"| {metric} | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    counts = summary["grouped"]["count"]
    for g in OUTCOME_GROUPS:
        if not counts[g]["all"]:
            continue
        lines.append(f"| {g} | " + " | ".join(_fmt(summary["grouped"][metric][g][c]) for c in cols) + " |")
    return "\n".join(lines)
