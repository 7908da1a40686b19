"""Per-axis sign-flip diagnostic (paper section 6): does the critic prefer the right direction along each
axis, and how often would a residual defined in the TCP's own frame point the other way in the world?

On counterfactual branch points every axis has a ``+d`` and a ``-d`` candidate (world frame,
``rl.chunk_perturbations``) with true returns. Where those returns differ, the critic *agrees* when
``Q(+d) - Q(-d)`` has the sign of ``return(+d) - return(-d)``: a critic blind to actions agrees at
chance (50%; a tie counts half). A residual grid built in the TCP frame but executed as if world (the
frame mix-up the paper suspected) is inverted wherever the TCP's axis points against the world axis (a
tool x axis with a negative world-x component, a tool z axis pointing down for yaw): the ``tcp_flip``
rate. Read in the TCP frame, the critic's choice agrees with the truth on ``agree_if_tcp_frame``
of the points.
"""

from __future__ import annotations

import numpy as np

from lerobot_bboxpick import geometry

# Which entry of the TCP's rotation (tool -> world) is the world component of the tool's own axis.
_AXIS_ENTRY = {"x": (0, 0), "y": (1, 1), "z": (2, 2), "yaw": (2, 2)}


def tcp_flips(base_pose: np.ndarray, axis: str) -> np.ndarray:
    """(P,) bool: the tool's ``axis`` points against the world's at each pose10 in ``base_pose``."""
    if axis not in _AXIS_ENTRY:
        raise ValueError(f"axis={axis!r} is not one of {', '.join(_AXIS_ENTRY)}")
    rotation = geometry.pose9_to_mat(np.asarray(base_pose, dtype=np.float64)[:, :9])[:, :3, :3]
    row, col = _AXIS_ENTRY[axis]
    return rotation[:, row, col] < 0


def sign_agreement(q: np.ndarray, returns: np.ndarray, kinds: list[str], base_pose: np.ndarray) -> dict:
    """Per axis with ``<axis>+`` and ``<axis>-`` candidates in ``kinds``: the points whose true returns
    differ, how often the critic's ``q`` (P, C) prefers the better sign, how often the TCP frame flips
    that axis, and the agreement if the critic's choice were read in the TCP frame."""
    q, returns = np.asarray(q, dtype=np.float64), np.asarray(returns, dtype=np.float64)
    if q.shape != returns.shape or q.shape[1] != len(kinds):
        raise ValueError(f"q {q.shape} and returns {returns.shape} must both be (points, {len(kinds)})")
    out = {}
    for axis in _AXIS_ENTRY:
        plus = [i for i, k in enumerate(kinds) if k.startswith(axis + "+")]
        minus = [i for i, k in enumerate(kinds) if k.startswith(axis + "-")]
        if not plus or not minus:
            continue
        true_diff = returns[:, plus[0]] - returns[:, minus[0]]
        rows = np.flatnonzero(true_diff != 0)
        flips = tcp_flips(base_pose, axis)
        q_diff = q[rows, plus[0]] - q[rows, minus[0]]
        # A tie (a critic blind to the action) is a coin flip: half an agreement.
        agree = np.where(q_diff == 0, 0.5, (np.sign(q_diff) == np.sign(true_diff[rows])).astype(float))
        in_tcp_frame = np.where(flips[rows], 1.0 - agree, agree)
        out[axis] = {
            "points": int(len(rows)),
            "agree": float(agree.mean()) if len(rows) else None,
            "plus_better": float((true_diff[rows] > 0).mean()) if len(rows) else None,
            "tcp_flip": float(flips.mean()) if len(flips) else None,
            "agree_if_tcp_frame": float(in_tcp_frame.mean()) if len(rows) else None,
        }
    return out


def sign_flip_table(columns: list[tuple[str, dict]]) -> str:
    """Markdown: one row per axis; per critic, its sign agreement (and in the TCP frame)."""

    def pct(x: float | None) -> str:
        return "-" if x is None else f"{x:.0%}"

    first = columns[0][1]
    header = ["axis", "points (returns differ)", "+d better", "TCP axis flipped"]
    for name, _ in columns:
        header += [f"{name}: agrees", f"{name}: agrees if read in TCP frame"]
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for axis, a in first.items():
        cells = [axis, str(a["points"]), pct(a["plus_better"]), pct(a["tcp_flip"])]
        for _, col in columns:
            c = col.get(axis, {})
            cells += [pct(c.get("agree")), pct(c.get("agree_if_tcp_frame"))]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
