"""Every outcome class (paper section 5.4, made strict in sim/outcome.py) comes out of a situation
that should produce it."""

import numpy as np

from lerobot_bboxpick.sim.expert import GRASP_HEIGHT, ScriptedExpert, Waypoint, grasp_rotation


def _run(env, actions) -> dict:
    info = {}
    for a in actions:
        _, _, _, _, info = env.step(a)
    return info


def _pose(xyz, R):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, xyz
    return T


def test_expert_pick_is_pick(grid_env):
    grid_env.reset(seed=3)
    expert = ScriptedExpert(np.random.default_rng(3))
    expert.reset(grid_env)
    speed_limited = 0
    while not expert.done:
        _, reward, _, _, info = grid_env.step(expert.act())
        speed_limited += info["speed_limited"]
    assert info["outcome"] == "pick" and info["is_success"] is True and reward == 1.0
    assert speed_limited == 0  # the demos move within the env's TCP speed limits
    # The brick really is up: >= 5 cm above the table, between the fingers.
    assert grid_env.brick_pose(grid_env.target)[2, 3] > 0.05


def test_picking_another_brick_is_wrong(grid_env):
    grid_env.reset(seed=4)
    other = (grid_env.target + 5) % 12
    expert = ScriptedExpert(np.random.default_rng(4))
    expert.reset(grid_env, brick=other)
    while not expert.done:
        _, reward, _, _, info = grid_env.step(expert.act())
    assert info["outcome"] == "wrong" and info["is_success"] is False and reward == 0.0
    assert grid_env.brick_pose(other)[2, 3] > 0.05 and grid_env.brick_pose(grid_env.target)[2, 3] < 0.01


def test_pressing_on_the_target_without_grasping_is_contact(grid_env):
    grid_env.reset(seed=5)
    B = grid_env.brick_pose(grid_env.target)
    R = grasp_rotation(float(np.arctan2(B[1, 0], B[0, 0])))
    top = B[:3, 3] + [0, 0, 0.03]  # closed fingertips 1 cm into the brick's top: they press on it
    plan = ScriptedExpert.through(
        grid_env.tcp_pose(),
        grid_env.gripper_width(),
        [
            Waypoint(_pose(top + [0, 0, 0.08], R), 0.0, 2.0),
            Waypoint(_pose(top - [0, 0, 0.012], R), 0.0, 1.0),
            Waypoint(_pose(top + [0, 0, 0.1], R), 0.0, 1.0),
        ],
        grid_env.options.fps,
    )
    info = _run(grid_env, plan)
    assert info["outcome"] == "contact" and info["is_success"] is False


def test_closing_on_air_is_empty(grid_env):
    grid_env.reset(seed=6)
    B = grid_env.brick_pose(grid_env.target)
    R = grasp_rotation(float(np.arctan2(B[1, 0], B[0, 0])))
    beside = B[:3, 3] + [0.0, 0.0, 0.12]  # 12 cm above the target: close, lift, nothing in hand
    plan = ScriptedExpert.through(
        grid_env.tcp_pose(),
        grid_env.gripper_width(),
        [
            Waypoint(_pose(beside, R), 0.075, 2.0),
            Waypoint(_pose(beside, R), 0.0, 0.6),
            Waypoint(_pose(beside + [0, 0, 0.05], R), 0.0, 0.6),
        ],
        grid_env.options.fps,
    )
    info = _run(grid_env, plan)
    assert info["outcome"] == "empty"
    heights = grid_env.data.xpos[grid_env.ids.brick_bodies, 2]
    assert np.abs(heights).max() < 0.005  # nothing moved


def test_episode_terminates_once_a_brick_is_lifted():
    from lerobot_bboxpick.sim.env import LegoPickEnv

    env = LegoPickEnv(setting="grid_id", terminate_on_lift=True)
    env.reset(seed=3)
    expert = ScriptedExpert(np.random.default_rng(3))
    expert.reset(env)
    steps = 0
    while True:
        _, _, terminated, truncated, info = env.step(expert.act())
        steps += 1
        if terminated or truncated:
            break
    env.close()
    assert terminated and info["outcome"] == "pick"
    assert steps < len(expert._actions)  # it ended once the pick was decided, before the carry back


def test_grasp_height_keeps_fingertips_above_the_table():
    assert 0.0 < GRASP_HEIGHT < 0.0192


def test_a_thrown_brick_ends_the_episode_as_sim_unstable(grid_env):
    """A brick far faster than the gripper can move it means the contact solver blew up: the env ends
    the episode and flags it, instead of scoring whatever the explosion did. A normal pick stays below
    the threshold with a wide margin."""
    from lerobot_bboxpick.sim.outcome import UNSTABLE_BRICK_SPEED

    obs, info = grid_env.reset(seed=3)
    expert = ScriptedExpert(np.random.default_rng(3))
    expert.reset(grid_env)
    while not expert.done:
        _, _, terminated, _, info = grid_env.step(expert.act())
    assert info["outcome"] == "pick" and not info["sim_unstable"] and not terminated
    assert grid_env._tracker.peak_brick_speed < UNSTABLE_BRICK_SPEED / 2

    obs, info = grid_env.reset(seed=3)
    hold = obs["agent_pos"].copy()
    other = (grid_env.target + 1) % 12
    dof = grid_env.ids.brick_dof[other]
    grid_env.data.qvel[dof : dof + 3] = [0.0, 12.0, 3.0]  # as an exploding contact would throw it
    _, _, terminated, _, info = grid_env.step(hold)
    assert info["sim_unstable"] and terminated
    assert info["outcome"] == "empty"  # nothing tracked after the blow-up


# ------------------------------------------------------------------ the strict definition, scored directly
class _Contacts:
    def __init__(self, pairs: list[tuple[int, int]]) -> None:
        self.geom = np.array(pairs, dtype=int).reshape(-1, 2)


class _State:
    """The parts of MjData the tracker reads: contacts, brick velocities and heights."""

    def __init__(self, ids, heights: np.ndarray, held: list[int]) -> None:
        n_bodies = int(max(ids.brick_bodies)) + 1
        self.cvel = np.zeros((n_bodies, 6))
        self.xpos = np.zeros((n_bodies, 3))
        self.xpos[ids.brick_bodies, 2] = heights
        pairs = []
        for brick in held:  # both fingers on each held brick
            geom = int(np.flatnonzero(ids.brick_of_geom == brick)[0])
            pairs += [(int(ids.finger_geoms[0][0]), geom), (geom, int(ids.finger_geoms[1][0]))]
        self.contact = _Contacts(pairs)
        self.ncon = len(pairs)


def _score(grid_env, rest, frames):
    """Feed (heights, held bricks) per control step to a fresh tracker; return its outcome."""
    from lerobot_bboxpick.sim.outcome import OutcomeTracker

    tracker = OutcomeTracker(grid_env.ids, target=0, rest_heights=rest)
    for heights, held in frames:
        state = _State(grid_env.ids, heights, held)
        tracker.update(state)
        tracker.end_step(state)
    return tracker.outcome


def test_pick_needs_the_lift_held_for_a_full_second(grid_env):
    from lerobot_bboxpick.sim.outcome import HOLD_STEPS

    rest = np.zeros(12)
    up = rest.copy()
    up[0] = 0.06
    assert _score(grid_env, rest, [(up, [0])] * HOLD_STEPS) == "pick"
    # Lifted and dropped within the second: contact, however high it went.
    dropped = [(up, [0])] * (HOLD_STEPS - 1) + [(rest, [])] * 40
    assert _score(grid_env, rest, dropped) == "contact"
    # A hold interrupted once starts counting again.
    broken = [(up, [0])] * 10 + [(up, [])] + [(up, [0])] * (HOLD_STEPS - 1)
    assert _score(grid_env, rest, broken) == "contact"


def test_lifting_the_target_with_a_neighbour_is_not_a_pick(grid_env):
    rest = np.zeros(12)
    both = rest.copy()
    both[[0, 1]] = 0.06
    assert _score(grid_env, rest, [(both, [0, 1])] * 40) == "contact"
    # The neighbour carried along without being gripped counts too (4 cm up: lifted).
    carried = rest.copy()
    carried[0], carried[1] = 0.06, 0.04
    assert _score(grid_env, rest, [(carried, [0])] * 40) == "contact"
    # A neighbour merely knocked onto another brick (2 cm) does not spoil the pick.
    knocked = rest.copy()
    knocked[0], knocked[1] = 0.06, 0.0192
    assert _score(grid_env, rest, [(knocked, [0])] * 40) == "pick"
    # Another brick alone held for the second: wrong.
    other = rest.copy()
    other[5] = 0.06
    assert _score(grid_env, rest, [(other, [5])] * 40) == "wrong"


def test_a_stacked_brick_must_rise_5_cm_above_where_it_rested(grid_env):
    rest = np.zeros(12)
    rest[0] = 0.0192  # the target lies on another brick
    lifted_3cm = rest.copy()
    lifted_3cm[0] += 0.035  # 5.4 cm above the table, 3.5 cm above its rest
    assert _score(grid_env, rest, [(lifted_3cm, [0])] * 40) == "contact"
    lifted_5cm = rest.copy()
    lifted_5cm[0] += 0.052
    assert _score(grid_env, rest, [(lifted_5cm, [0])] * 40) == "pick"


def test_a_real_grasp_opened_right_after_the_lift_is_contact(grid_env):
    """In MuJoCo: grasp the target, lift it 8 cm, open at once: it was up, but not held for 1 s."""
    from lerobot_bboxpick.sim.outcome import LIFT_HEIGHT

    grid_env.reset(seed=7)
    B = grid_env.brick_pose(grid_env.target)
    R = grasp_rotation(float(np.arctan2(B[1, 0], B[0, 0])))
    p = B[:3, 3]
    plan = ScriptedExpert.through(
        grid_env.tcp_pose(),
        grid_env.gripper_width(),
        [
            Waypoint(_pose(p + [0, 0, 0.09], R), 0.075, 2.2),
            Waypoint(_pose(p + [0, 0, GRASP_HEIGHT], R), 0.075, 1.2),
            Waypoint(_pose(p + [0, 0, GRASP_HEIGHT], R), 0.0, 0.8),
            Waypoint(_pose(p + [0, 0, 0.14], R), 0.0, 0.6),
            Waypoint(_pose(p + [0, 0, 0.14], R), 0.075, 0.2),
            Waypoint(_pose(p + [0, 0, 0.14], R), 0.075, 1.5),
        ],
        grid_env.options.fps,
    )
    info = _run(grid_env, plan)
    assert grid_env._tracker.max_rise[grid_env.target] > LIFT_HEIGHT  # it really was up
    assert grid_env._tracker.hold_steps.max() == 0  # and is down again
    assert info["outcome"] == "contact" and not info["is_success"]


def test_the_expert_pick_is_decided_after_a_second_of_holding():
    """terminate_on_lift ends the episode when the pick is decided: 20 steps after the lift began."""
    from lerobot_bboxpick.sim.env import LegoPickEnv
    from lerobot_bboxpick.sim.outcome import HOLD_STEPS, LIFT_HEIGHT

    env = LegoPickEnv(setting="pile_id", terminate_on_lift=True)
    env.reset(seed=2)
    expert = ScriptedExpert(np.random.default_rng(2))
    expert.reset(env)
    first_up = None
    steps = 0
    while True:
        _, _, terminated, truncated, info = env.step(expert.act())
        steps += 1
        if first_up is None and env._tracker.max_rise[env.target] >= LIFT_HEIGHT:
            first_up = steps
        if terminated or truncated:
            break
    env.close()
    assert info["outcome"] == "pick" and terminated
    assert steps - first_up == HOLD_STEPS - 1
