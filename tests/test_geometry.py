import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_bboxpick import geometry as g

RNG_SEED = 0


def _random_pose9(shape, seed=RNG_SEED):
    rng = np.random.default_rng(seed)
    n = int(np.prod(shape))
    R = Rotation.random(n, random_state=seed).as_matrix()
    pos = rng.uniform(-1.0, 1.0, size=(n, 3))
    return np.concatenate([pos, g.mat_to_rot6d(R)], axis=-1).reshape(*shape, 9)


def _random_pose10(shape, seed=RNG_SEED):
    rng = np.random.default_rng(seed + 1)
    grip = rng.uniform(0.0, 0.08, size=(*shape, 1))
    return np.concatenate([_random_pose9(shape, seed), grip], axis=-1)


def _rz(deg):
    return Rotation.from_euler("z", deg, degrees=True).as_matrix()


# --------------------------------------------------------------------------- rotations
def test_rot6d_round_trip_1000():
    R = Rotation.random(1000, random_state=RNG_SEED).as_matrix()
    d6 = g.mat_to_rot6d(R)
    assert d6.shape == (1000, 6)
    np.testing.assert_allclose(d6[:, :3], R[:, 0, :])  # first row
    np.testing.assert_allclose(d6[:, 3:], R[:, 1, :])  # second row
    np.testing.assert_allclose(g.rot6d_to_mat(d6), R, atol=1e-9)


def test_rot6d_batched_leading_dims():
    R = Rotation.random(24, random_state=1).as_matrix().reshape(2, 3, 4, 3, 3)
    back = g.rot6d_to_mat(g.mat_to_rot6d(R))
    assert back.shape == (2, 3, 4, 3, 3)
    np.testing.assert_allclose(back, R, atol=1e-9)


def test_gram_schmidt_perturbed_is_orthonormal():
    rng = np.random.default_rng(3)
    d6 = g.mat_to_rot6d(Rotation.random(200, random_state=3).as_matrix())
    noisy = d6 + 0.2 * rng.standard_normal(d6.shape)
    noisy[:, :3] *= 3.0  # non-unit rows
    R = g.rot6d_to_mat(noisy)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # first row is the normalised first input row (Gram-Schmidt, not SVD)
    a1 = noisy[:, :3]
    np.testing.assert_allclose(R[:, 0, :], a1 / np.linalg.norm(a1, axis=-1, keepdims=True), atol=1e-12)


def test_axis_angle_round_trip_and_known():
    R = Rotation.random(50, random_state=4).as_matrix().reshape(5, 10, 3, 3)
    v = g.mat_to_axis_angle(R)
    assert v.shape == (5, 10, 3)
    np.testing.assert_allclose(g.axis_angle_to_mat(v), R, atol=1e-9)
    np.testing.assert_allclose(g.axis_angle_to_mat(np.array([0, 0, np.pi / 2])), _rz(90), atol=1e-12)
    np.testing.assert_allclose(g.mat_to_axis_angle(_rz(90)), [0, 0, np.pi / 2], atol=1e-12)


def test_quat_wxyz_known_and_round_trip():
    c = np.cos(np.pi / 4)
    np.testing.assert_allclose(g.mat_to_quat_wxyz(_rz(90)), [c, 0, 0, c], atol=1e-12)
    np.testing.assert_allclose(g.quat_wxyz_to_mat(np.array([c, 0, 0, c])), _rz(90), atol=1e-12)
    np.testing.assert_allclose(g.quat_wxyz_to_mat(np.array([1.0, 0, 0, 0])), np.eye(3), atol=1e-15)
    R = Rotation.random(100, random_state=5).as_matrix().reshape(4, 25, 3, 3)
    q = g.mat_to_quat_wxyz(R)
    assert q.shape == (4, 25, 4)
    assert np.all(q[..., 0] >= 0)
    np.testing.assert_allclose(g.quat_wxyz_to_mat(q), R, atol=1e-9)
    np.testing.assert_allclose(g.quat_wxyz_to_mat(-q), R, atol=1e-9)  # q and -q: same rotation


# --------------------------------------------------------------------------- pose9
def test_pose9_mat_round_trip():
    p9 = _random_pose9((3, 7))
    T = g.pose9_to_mat(p9)
    assert T.shape == (3, 7, 4, 4)
    np.testing.assert_allclose(T[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], (3, 7, 4)))
    np.testing.assert_allclose(T[..., :3, 3], p9[..., :3])
    np.testing.assert_allclose(g.mat_to_pose9(T), p9, atol=1e-9)


def test_pose9_pos_axis_angle_round_trip():
    p9 = _random_pose9((6, 2))
    pos, rv = g.pose9_to_pos_axis_angle(p9)
    assert pos.shape == rv.shape == (6, 2, 3)
    np.testing.assert_allclose(g.pos_axis_angle_to_pose9(pos, rv), p9, atol=1e-9)


# --------------------------------------------------------------------------- relative / absolute
def test_relative_absolute_round_trip_numpy():
    p9 = _random_pose9((4, 16))
    base = _random_pose9((4, 1), seed=7)
    rel = g.relative_pose9(p9, base)
    assert rel.shape == (4, 16, 9)
    np.testing.assert_allclose(g.absolute_pose9(rel, base), p9, atol=1e-9)
    # rel is really inv(T_base) @ T
    expected = g.mat_to_pose9(np.linalg.inv(g.pose9_to_mat(base)) @ g.pose9_to_mat(p9))
    np.testing.assert_allclose(rel, expected, atol=1e-9)


def test_relative_of_base_to_itself_is_identity():
    base = _random_pose9((5,), seed=9)
    np.testing.assert_allclose(g.relative_pose9(base, base), np.tile(g.IDENTITY_POSE9, (5, 1)), atol=1e-12)
    t = torch.as_tensor(base, dtype=torch.float32)
    ident = torch.as_tensor(g.IDENTITY_POSE9, dtype=torch.float32).expand(5, 9)
    torch.testing.assert_close(g.relative_pose9_torch(t, t), ident, atol=1e-6, rtol=0)


def test_known_relative_pose():
    rot = g.mat_to_rot6d(_rz(90))
    base = np.concatenate([[1.0, 0.0, 0.0], rot])
    target = np.concatenate([[1.0, 1.0, 0.0], rot])
    rel = g.relative_pose9(target, base)
    np.testing.assert_allclose(rel, [1, 0, 0, 1, 0, 0, 0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(g.absolute_pose9(rel, base), target, atol=1e-12)


def test_relative_absolute_pose10_gripper_passthrough():
    p10 = _random_pose10((3, 8))
    base = _random_pose10((3, 1), seed=11)
    rel = g.relative_pose10(p10, base)
    np.testing.assert_allclose(rel[..., 9], p10[..., 9])
    np.testing.assert_allclose(rel[..., :9], g.relative_pose9(p10[..., :9], base[..., :9]), atol=1e-12)
    np.testing.assert_allclose(g.absolute_pose10(rel, base), p10, atol=1e-9)


def test_torch_round_trip_float32_and_matches_numpy():
    p9 = _random_pose9((4, 16), seed=12)
    base = _random_pose9((4, 1), seed=13)
    tp, tb = torch.as_tensor(p9, dtype=torch.float32), torch.as_tensor(base, dtype=torch.float32)
    rel_t = g.relative_pose9_torch(tp, tb)
    assert rel_t.shape == (4, 16, 9) and rel_t.dtype == torch.float32
    torch.testing.assert_close(g.absolute_pose9_torch(rel_t, tb), tp, atol=1e-5, rtol=0)
    np.testing.assert_allclose(rel_t.numpy(), g.relative_pose9(p9, base), atol=1e-5)
    rel_np = g.relative_pose9(p9, base)
    abs_t = g.absolute_pose9_torch(torch.as_tensor(rel_np, dtype=torch.float32), tb)
    np.testing.assert_allclose(abs_t.numpy(), g.absolute_pose9(rel_np, base), atol=1e-5)


def test_torch_rot6d_to_mat_matches_numpy_on_noisy_input():
    rng = np.random.default_rng(14)
    d6 = rng.standard_normal((30, 6))
    R_t = g.rot6d_to_mat_torch(torch.as_tensor(d6))
    np.testing.assert_allclose(R_t.numpy(), g.rot6d_to_mat(d6), atol=1e-12)


# --------------------------------------------------------------------------- mirroring
def test_mirror_pose10():
    p10 = _random_pose10((20,), seed=15)
    m = g.mirror_pose10(p10)
    R, Rm = g.rot6d_to_mat(p10[:, 3:9]), g.rot6d_to_mat(m[:, 3:9])
    M = np.diag([1.0, -1.0, 1.0])
    np.testing.assert_allclose(np.linalg.det(Rm), 1.0, atol=1e-12)
    np.testing.assert_allclose(m[:, :3], p10[:, :3] * [1, -1, 1])
    np.testing.assert_allclose(m[:, 9], p10[:, 9])
    np.testing.assert_allclose(Rm[:, :, 2], R[:, :, 2] @ M.T, atol=1e-12)  # approach z' = M z
    np.testing.assert_allclose(Rm[:, :, 1], R[:, :, 1] @ M.T, atol=1e-12)  # camera-down y' = M y
    np.testing.assert_allclose(Rm[:, :, 0], -(R[:, :, 0] @ M.T), atol=1e-12)  # finger x' = -M x
    np.testing.assert_allclose(g.mirror_pose10(m), p10, atol=1e-12)


def test_mirror_pose10_known_and_relative_consistency():
    # gripper pointing down (z = -world z) at yaw 30 deg. The camera-side y axis is mirrored (not the finger
    # axis), so the mirrored yaw is 180 - 30 = 150 deg (= -30 deg plus a half-turn about the approach axis).
    down = Rotation.from_euler("x", 180, degrees=True).as_matrix()
    R = _rz(30) @ down
    p10 = np.concatenate([[0.3, 0.2, 0.1], g.mat_to_rot6d(R), [0.04]])
    m = g.mirror_pose10(p10)
    np.testing.assert_allclose(m[:3], [0.3, -0.2, 0.1])
    np.testing.assert_allclose(g.rot6d_to_mat(m[3:9]), _rz(150) @ down, atol=1e-12)
    np.testing.assert_allclose(g.rot6d_to_mat(m[3:9]), _rz(-30) @ down @ _rz(180), atol=1e-12)
    # gripper-frame coordinates of a mirrored scene point only flip x: c' = D c
    q = np.array([0.5, 0.4, 0.0])
    c = R.T @ (q - p10[:3])
    c_m = g.rot6d_to_mat(m[3:9]).T @ (q * [1, -1, 1] - m[:3])
    np.testing.assert_allclose(c_m, c * [-1, 1, 1], atol=1e-12)


def test_mirror_image_bbox():
    np.testing.assert_allclose(g.mirror_image_bbox(np.array([0.1, 0.2, 0.3, 0.4])), [0.7, 0.2, 0.9, 0.4])
    b = np.random.default_rng(16).uniform(size=(3, 5, 4))
    np.testing.assert_allclose(g.mirror_image_bbox(g.mirror_image_bbox(b)), b, atol=1e-15)


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("fn", "args", "name"),
    [
        (g.rot6d_to_mat, (np.zeros(5),), "d6"),
        (g.mat_to_rot6d, (np.zeros((3, 4)),), "R"),
        (g.pose9_to_mat, (np.zeros((2, 10)),), "p9"),
        (g.mat_to_pose9, (np.zeros((3, 3)),), "T"),
        (g.quat_wxyz_to_mat, (np.zeros(3),), "q"),
        (g.pos_axis_angle_to_pose9, (np.zeros(3), np.zeros(4)), "rotvec"),
        (g.relative_pose9, (np.zeros(9), np.zeros(10)), "base_p9"),
        (g.absolute_pose10, (np.zeros(9), np.zeros(10)), "rel10"),
        (g.mirror_pose10, (np.zeros(9),), "p10"),
        (g.mirror_image_bbox, (np.zeros(5),), "bbox"),
        (g.relative_pose9_torch, (torch.zeros(2, 9), torch.zeros(2, 6)), "base_p9"),
        (g.absolute_pose9_torch, (torch.zeros(2, 10), torch.zeros(2, 9)), "rel"),
    ],
)
def test_bad_shapes_raise(fn, args, name):
    with pytest.raises(ValueError, match=rf"^{name} must have shape"):
        fn(*args)


def test_mirror_bad_axis():
    with pytest.raises(ValueError, match="axis"):
        g.mirror_pose10(np.zeros(10), axis="w")
