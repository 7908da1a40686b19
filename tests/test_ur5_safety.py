"""SafetyLimits of the ur5 robot: refusals name the field, speed and acceleration limits with numbers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lerobot_bboxpick.robots.ur5.safety import SafetyLimits, UnsafeActionError

VALID = [0.5, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.05]


def with_value(i: int, v: float) -> list[float]:
    a = list(VALID)
    a[i] = v
    return a


def test_a_valid_action_passes_as_float64():
    a = SafetyLimits().check_pose10(VALID)
    assert a.dtype == np.float64 and a.shape == (10,)


@pytest.mark.parametrize("shape", [(9,), (11,), (2, 10)])
def test_wrong_shape(shape):
    with pytest.raises(UnsafeActionError, match=rf"10 values .*got shape \({shape[0]}"):
        SafetyLimits().check_pose10(np.zeros(shape))


@pytest.mark.parametrize(("i", "name"), [(0, "x"), (4, "r01"), (9, "gripper_width")])
@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_names_the_field(i, name, bad):
    with pytest.raises(UnsafeActionError, match=rf"\['{name}'\] are not finite"):
        SafetyLimits().check_pose10(with_value(i, bad))


@pytest.mark.parametrize(
    ("i", "v", "axis"), [(0, 0.1, "x"), (0, 0.9, "x"), (1, -0.6, "y"), (2, -0.01, "z"), (2, 0.6, "z")]
)
def test_out_of_box_names_the_axis_and_the_box(i, v, axis):
    with pytest.raises(UnsafeActionError, match=rf"field {axis}=.* outside the workspace box"):
        SafetyLimits().check_pose10(with_value(i, v))


@pytest.mark.parametrize(("rows", "name"), [(slice(3, 6), "r00..r02"), (slice(6, 9), "r10..r12")])
def test_zero_rot6d_row(rows, name):
    a = np.array(VALID)
    a[rows] = 0.0
    with pytest.raises(UnsafeActionError, match=rf"fields {name} \(a rot6d row\) must not be all zero"):
        SafetyLimits().check_pose10(a)


@pytest.mark.parametrize("width", [-0.01, 0.0901])
def test_gripper_range(width):
    with pytest.raises(UnsafeActionError, match=r"gripper_width=.* outside \[0, 0.09\]"):
        SafetyLimits().check_pose10(with_value(9, width))
    SafetyLimits().check_pose10(with_value(9, 0.09))  # the widest allowed


def test_bad_limits_name_the_field():
    with pytest.raises(ValueError, match="max_tcp_speed"):
        SafetyLimits(max_tcp_speed=0.0)
    with pytest.raises(ValueError, match="workspace_low"):
        SafetyLimits(workspace_low=[0.9, 0.0, 0.0])


def _pose(x: float, rotvec=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = [x, 0.0, 0.2]
    return T


def test_speed_limit_keeps_the_straight_path():
    s = SafetyLimits(max_tcp_speed=0.5)
    T, limited = s.limit_velocity(_pose(0.4), _pose(0.5), dt=0.05)  # 0.1 m asked, 0.5 m/s * 0.05 s allowed
    assert limited
    assert T[:3, 3] == pytest.approx([0.425, 0.0, 0.2], abs=1e-12)
    T, limited = s.limit_velocity(_pose(0.4), _pose(0.42), dt=0.05)  # 0.02 m: within the bound
    assert not limited and T[0, 3] == pytest.approx(0.42)


def test_angular_speed_limit():
    s = SafetyLimits(max_tcp_angular_speed=1.5)
    T, limited = s.limit_velocity(_pose(0.4), _pose(0.4, (0.0, 0.0, 0.5)), dt=0.05)
    assert limited
    assert Rotation.from_matrix(T[:3, :3]).as_rotvec() == pytest.approx([0.0, 0.0, 0.075], abs=1e-12)


def test_acceleration_limit_from_rest_and_at_speed():
    s = SafetyLimits(max_tcp_speed=0.5, max_tcp_acceleration=2.0)
    # From rest: (0 + 2.0 * 0.05) m/s for 0.05 s = 5 mm.
    T, limited = s.limit_velocity(_pose(0.4), _pose(0.5), 0.05, v_prev=np.zeros(3))
    assert limited and T[0, 3] == pytest.approx(0.405, abs=1e-12)
    # At 0.2 m/s: (0.2 + 0.1) * 0.05 = 15 mm.
    T, _ = s.limit_velocity(_pose(0.4), _pose(0.5), 0.05, v_prev=np.array([0.2, 0.0, 0.0]))
    assert T[0, 3] == pytest.approx(0.415, abs=1e-12)
    # At 0.48 m/s the speed bound (25 mm) binds before the acceleration one (29 mm).
    T, _ = s.limit_velocity(_pose(0.4), _pose(0.5), 0.05, v_prev=np.array([0.48, 0.0, 0.0]))
    assert T[0, 3] == pytest.approx(0.425, abs=1e-12)
