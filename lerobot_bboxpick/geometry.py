"""Pose conversions: the one place in the project that owns them.

Conventions (match UMI's ``pose_util``):

* ``rot6d`` = the first two ROWS of the 3x3 rotation matrix, row-major:
  ``R[0,0], R[0,1], R[0,2], R[1,0], R[1,1], R[1,2]``. Decoding uses Gram-Schmidt on those rows.
* ``pose9`` = position (3) + rot6d (6); ``pose10`` = pose9 + gripper width (1).
* A pose ``T`` maps gripper-frame points to the table (world) frame; the columns of ``R`` are the gripper
  axes in the world frame: x = finger-opening axis, y = camera "down" axis, z = approach axis.
* Quaternions are ``(w, x, y, z)`` (MuJoCo); scipy's ``(x, y, z, w)`` stays internal.

All numpy functions return float64 and accept arbitrary leading batch dims ``(..., k)``.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

IDENTITY_POSE9 = np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], dtype=np.float64)


def _vec(x, k: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != k:
        raise ValueError(f"{name} must have shape (..., {k}), got {a.shape}")
    return a


def _mat(x, n: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 2 or a.shape[-2:] != (n, n):
        raise ValueError(f"{name} must have shape (..., {n}, {n}), got {a.shape}")
    return a


def _t(R: np.ndarray) -> np.ndarray:
    return np.swapaxes(R, -1, -2)


# --------------------------------------------------------------------------- rotations
def mat_to_rot6d(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation -> (..., 6): first two rows, row-major."""
    R = _mat(R, 3, "R")
    return R[..., :2, :].reshape(R.shape[:-2] + (6,)).copy()


def rot6d_to_mat(d6: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) via Gram-Schmidt; robust to non-orthonormal input (rows b1, b2, b3)."""
    d6 = _vec(d6, 6, "d6")
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / np.linalg.norm(a1, axis=-1, keepdims=True)
    b2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = b2 / np.linalg.norm(b2, axis=-1, keepdims=True)
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-2)


def axis_angle_to_mat(v: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vector -> (..., 3, 3)."""
    v = _vec(v, 3, "v")
    return Rotation.from_rotvec(v.reshape(-1, 3)).as_matrix().reshape(v.shape[:-1] + (3, 3))


def mat_to_axis_angle(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 3) rotation vector (angle in [0, pi])."""
    R = _mat(R, 3, "R")
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(R.shape[:-2] + (3,))


def quat_wxyz_to_mat(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternion (w, x, y, z), normalised internally -> (..., 3, 3)."""
    q = _vec(q, 4, "q")
    xyzw = q.reshape(-1, 4)[:, [1, 2, 3, 0]]
    return Rotation.from_quat(xyzw).as_matrix().reshape(q.shape[:-1] + (3, 3))


def mat_to_quat_wxyz(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 4) unit quaternion (w, x, y, z), canonical sign (w >= 0)."""
    R = _mat(R, 3, "R")
    xyzw = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat(canonical=True)
    return xyzw[:, [3, 0, 1, 2]].reshape(R.shape[:-2] + (4,))


# --------------------------------------------------------------------------- pose9 <-> matrices
def pose9_to_mat(p9: np.ndarray) -> np.ndarray:
    """(..., 9) -> (..., 4, 4) homogeneous transform."""
    p9 = _vec(p9, 9, "p9")
    T = np.zeros(p9.shape[:-1] + (4, 4))
    T[..., :3, :3] = rot6d_to_mat(p9[..., 3:])
    T[..., :3, 3] = p9[..., :3]
    T[..., 3, 3] = 1.0
    return T


def mat_to_pose9(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) homogeneous transform -> (..., 9)."""
    T = _mat(T, 4, "T")
    return np.concatenate([T[..., :3, 3], mat_to_rot6d(T[..., :3, :3])], axis=-1)


def pose9_to_pos_axis_angle(p9: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., 9) -> (position (..., 3), rotation vector (..., 3))."""
    p9 = _vec(p9, 9, "p9")
    return p9[..., :3].copy(), mat_to_axis_angle(rot6d_to_mat(p9[..., 3:]))


def pos_axis_angle_to_pose9(pos: np.ndarray, rotvec: np.ndarray) -> np.ndarray:
    """Position (..., 3) + rotation vector (..., 3) -> (..., 9) (leading dims broadcast)."""
    pos, rotvec = _vec(pos, 3, "pos"), _vec(rotvec, 3, "rotvec")
    pos, rotvec = np.broadcast_arrays(pos, rotvec)
    return np.concatenate([pos, mat_to_rot6d(axis_angle_to_mat(rotvec))], axis=-1)


# --------------------------------------------------------------------------- relative / absolute
def relative_pose9(p9: np.ndarray, base_p9: np.ndarray) -> np.ndarray:
    """inv(T_base) @ T: ``p9`` expressed in the ``base_p9`` frame; base broadcasts over leading dims."""
    p9, base_p9 = _vec(p9, 9, "p9"), _vec(base_p9, 9, "base_p9")
    Rb_t = _t(rot6d_to_mat(base_p9[..., 3:]))
    R = Rb_t @ rot6d_to_mat(p9[..., 3:])
    pos = (Rb_t @ (p9[..., :3] - base_p9[..., :3])[..., None])[..., 0]
    return np.concatenate([pos, mat_to_rot6d(R)], axis=-1)


def absolute_pose9(rel_p9: np.ndarray, base_p9: np.ndarray) -> np.ndarray:
    """T_base @ T_rel: inverse of :func:`relative_pose9`."""
    rel_p9, base_p9 = _vec(rel_p9, 9, "rel_p9"), _vec(base_p9, 9, "base_p9")
    Rb = rot6d_to_mat(base_p9[..., 3:])
    R = Rb @ rot6d_to_mat(rel_p9[..., 3:])
    pos = (Rb @ rel_p9[..., :3, None])[..., 0] + base_p9[..., :3]
    return np.concatenate([pos, mat_to_rot6d(R)], axis=-1)


def _with_gripper(p9: np.ndarray, grip: np.ndarray) -> np.ndarray:
    return np.concatenate([p9, np.broadcast_to(grip, p9.shape[:-1] + (1,))], axis=-1)


def relative_pose10(p10: np.ndarray, base_p10: np.ndarray) -> np.ndarray:
    """:func:`relative_pose9` on the first 9 dims; gripper width (last dim) of ``p10`` kept absolute."""
    p10, base_p10 = _vec(p10, 10, "p10"), _vec(base_p10, 10, "base_p10")
    return _with_gripper(relative_pose9(p10[..., :9], base_p10[..., :9]), p10[..., 9:])


def absolute_pose10(rel10: np.ndarray, base_p10: np.ndarray) -> np.ndarray:
    """:func:`absolute_pose9` on the first 9 dims; gripper width of ``rel10`` passed through."""
    rel10, base_p10 = _vec(rel10, 10, "rel10"), _vec(base_p10, 10, "base_p10")
    return _with_gripper(absolute_pose9(rel10[..., :9], base_p10[..., :9]), rel10[..., 9:])


# --------------------------------------------------------------------------- torch (policy processor)
def _check_torch(x: torch.Tensor, k: int, name: str) -> None:
    if x.ndim < 1 or x.shape[-1] != k:
        raise ValueError(f"{name} must have shape (..., {k}), got {tuple(x.shape)}")


def rot6d_to_mat_torch(d6: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """Torch Gram-Schmidt: (..., 6) -> (..., 3, 3) with rows (b1, b2, b3)."""
    _check_torch(d6, 6, "d6")
    b1 = torch.nn.functional.normalize(d6[..., :3], dim=-1, eps=eps)
    a2 = d6[..., 3:]
    b2 = torch.nn.functional.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1, eps=eps)
    return torch.stack([b1, b2, torch.linalg.cross(b1, b2, dim=-1)], dim=-2)


def _pose9_from_torch(pos: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
    return torch.cat([pos, R[..., :2, :].flatten(-2)], dim=-1)


def relative_pose9_torch(p9: torch.Tensor, base_p9: torch.Tensor) -> torch.Tensor:
    """Torch :func:`relative_pose9`; e.g. p9 (B, T, 9) with base (B, 1, 9). Output dtype follows ``p9``."""
    _check_torch(p9, 9, "p9")
    _check_torch(base_p9, 9, "base_p9")
    base_p9 = base_p9.to(dtype=p9.dtype, device=p9.device)
    Rb_t = rot6d_to_mat_torch(base_p9[..., 3:]).transpose(-1, -2)
    R = Rb_t @ rot6d_to_mat_torch(p9[..., 3:])
    pos = (Rb_t @ (p9[..., :3] - base_p9[..., :3]).unsqueeze(-1)).squeeze(-1)
    return _pose9_from_torch(pos, R)


def absolute_pose9_torch(rel: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """Torch :func:`absolute_pose9` (T_base @ T_rel), base broadcastable over leading dims."""
    _check_torch(rel, 9, "rel")
    _check_torch(base, 9, "base")
    base = base.to(dtype=rel.dtype, device=rel.device)
    Rb = rot6d_to_mat_torch(base[..., 3:])
    R = Rb @ rot6d_to_mat_torch(rel[..., 3:])
    pos = (Rb @ rel[..., :3].unsqueeze(-1)).squeeze(-1) + base[..., :3]
    return _pose9_from_torch(pos, R)


def relative_pose10_torch(poses: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """UMI's ``inv(T_base) @ T`` on the pose9 part of (..., T, 10) poses, base (..., 10); width kept."""
    rel9 = relative_pose9_torch(poses[..., :9], base[..., None, :9])
    return torch.cat([rel9, poses[..., 9:].to(rel9.dtype)], dim=-1)


def absolute_pose10_torch(rel: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """``T_base @ T_rel`` on (..., T, 10) relative poses, base (..., 10); width kept absolute."""
    abs9 = absolute_pose9_torch(rel[..., :9], base[..., None, :9])
    return torch.cat([abs9, rel[..., 9:]], dim=-1)


# --------------------------------------------------------------------------- mirroring (augmentation)
def mirror_pose10(p10: np.ndarray, axis: str = "y") -> np.ndarray:
    """Mirror table-frame poses across the plane ``axis = 0`` (default y = 0, the x-z plane).

    With ``M`` the reflection (``diag(1, -1, 1)`` for "y"): position ``p' = M p``; the approach axis
    and camera-down axis are mirrored, ``z' = M z``, ``y' = M y``, and the finger axis is chosen so
    the frame stays right-handed, ``x' = y' x z' = det(M) M (y x z) = -M x``. Hence
    ``R' = M R D`` with ``D = diag(-1, 1, 1)``, ``det R' = +1``, and mirroring twice is the identity.
    Gripper width is unchanged. A scene point's gripper-frame coordinates map ``c' = D c``: only the
    gripper x coordinate flips (see :func:`mirror_image_bbox`).
    """
    p10 = _vec(p10, 10, "p10")
    if axis not in ("x", "y", "z"):
        raise ValueError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    m = np.ones(3)
    m["xyz".index(axis)] = -1.0
    d = np.array([-1.0, 1.0, 1.0])
    R = rot6d_to_mat(p10[..., 3:9])
    R_m = m[:, None] * R * d[None, :]  # M @ R @ D for diagonal M, D
    return np.concatenate([m * p10[..., :3], mat_to_rot6d(R_m), p10[..., 9:]], axis=-1)


def mirror_image_bbox(bbox: np.ndarray) -> np.ndarray:
    """Normalised ``[x0, y0, x1, y1]`` (..., 4) -> horizontally flipped box matching :func:`mirror_pose10`.

    The wrist camera's image x axis is the gripper x axis, which is the only gripper-frame coordinate
    the mirror flips, so the image flips left-right: ``x0' = 1 - x1``, ``x1' = 1 - x0``, y unchanged.
    Exact when the principal point is at the image centre and the camera sits in the gripper's y-z plane.
    """
    b = _vec(bbox, 4, "bbox")
    return np.stack([1.0 - b[..., 2], b[..., 1], 1.0 - b[..., 0], b[..., 3]], axis=-1)
