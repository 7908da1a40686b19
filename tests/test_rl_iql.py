"""IQL recovers the known values of a small chain MDP (one-hot states and actions)."""

import numpy as np
import pytest
import torch

from lerobot_bboxpick.rl.iql import (
    IqlBatch,
    IqlCritic,
    IqlDims,
    expectile_loss,
    iql_step,
    polyak_update,
    td_target,
)

N_STATES = 5  # states 0..3 act; state 4 is the goal (absorbing, reward 1 on entering it)
GAMMA = 0.9
LEFT, RIGHT = 0, 1


def chain_transitions() -> list[tuple[int, int, float, bool, int]]:
    """Every (state, action) once: the behaviour policy picks left / right with equal weight."""
    out = []
    for s in range(N_STATES - 1):
        nxt = max(s - 1, 0)
        out.append((s, LEFT, 0.0, False, nxt))
        reached = s + 1 == N_STATES - 1
        out.append((s, RIGHT, 1.0 if reached else 0.0, reached, s + 1))
    return out


def expectile_fixed_point(tau: float) -> np.ndarray:
    """V(s) of IQL's fixed point: with two equally weighted actions the tau-expectile of {Q_L, Q_R}
    is ``tau * max + (1 - tau) * min`` exactly, so value iteration with that operator gives it."""
    v = np.zeros(N_STATES)
    for _ in range(500):
        q = np.zeros((N_STATES - 1, 2))
        for s, a, r, done, nxt in chain_transitions():
            q[s, a] = r + GAMMA * (0.0 if done else v[nxt])
        v[:-1] = tau * q.max(1) + (1 - tau) * q.min(1)
    return v[:-1]


def optimal_v() -> np.ndarray:
    """V*(s) = gamma ** (steps to the goal - 1)."""
    return np.array([GAMMA ** (N_STATES - 2 - s) for s in range(N_STATES - 1)])


def behaviour_v() -> np.ndarray:
    """V of the uniform behaviour policy: the tau = 0.5 fixed point, solved as a linear system."""
    n = N_STATES - 1
    A, b = np.eye(n), np.zeros(n)
    for s, _a, r, done, nxt in chain_transitions():
        b[s] += 0.5 * r
        if not done:
            A[s, nxt] -= 0.5 * GAMMA
    return np.linalg.solve(A, b)


def batch() -> IqlBatch:
    tr = chain_transitions()
    eye_s, eye_a = torch.eye(N_STATES), torch.eye(2)
    return IqlBatch(
        state=eye_s[[t[0] for t in tr]],
        action=eye_a[[t[1] for t in tr]],
        reward=torch.tensor([t[2] for t in tr]),
        done=torch.tensor([t[3] for t in tr]),
        discount=torch.full((len(tr),), GAMMA),
        next_state=eye_s[[t[4] for t in tr]],
    )


def _fit(tau: float, steps: int = 1000) -> np.ndarray:
    """Full-batch IQL; a fast Polyak rate (0.05) and lr keep this test short, the fixed point is the same."""
    torch.manual_seed(0)
    dims = IqlDims(N_STATES, 2, state_embed_dim=32, action_embed_dim=8, hidden_dim=64)
    critic = IqlCritic(dims)
    opt = torch.optim.Adam(critic.parameters(), lr=5e-3)
    b = batch()
    for _ in range(steps):
        iql_step(critic, b, opt, tau=tau, polyak=0.05)
    with torch.no_grad():
        return critic.v(torch.eye(N_STATES)[: N_STATES - 1]).numpy()


@pytest.fixture(scope="module")
def fitted() -> dict[float, np.ndarray]:
    """V after training at each expectile (one thread: tiny ops are slower with thread hand-offs)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return {tau: _fit(tau) for tau in (0.5, 0.7, 0.95)}
    finally:
        torch.set_num_threads(threads)


def test_reference_values_are_what_the_chain_says():
    # Sanity of the references themselves: tau -> 1 is V*, tau = 0.5 the behaviour value.
    np.testing.assert_allclose(expectile_fixed_point(0.999999), optimal_v(), atol=1e-4)
    np.testing.assert_allclose(expectile_fixed_point(0.5), behaviour_v(), atol=1e-9)
    np.testing.assert_allclose(optimal_v(), [0.729, 0.81, 0.9, 1.0])


@pytest.mark.parametrize("tau", [0.5, 0.7, 0.95])
def test_iql_recovers_the_expectile_fixed_point(fitted, tau):
    np.testing.assert_allclose(fitted[tau], expectile_fixed_point(tau), atol=0.01)


def test_expectile_near_one_approaches_max_q_and_half_the_behaviour_mean(fitted):
    v_hi, v_mid = fitted[0.95], fitted[0.5]
    assert np.abs(v_hi - optimal_v()).max() < 0.08  # 0.95: within the gap of the 0.95-expectile
    assert np.abs(v_mid - behaviour_v()).max() < 0.01
    # and the two are far apart: the expectile really selects the better action
    assert (v_hi - v_mid).min() > 0.15


def test_pure_functions_give_the_hand_computed_numbers():
    diff = torch.tensor([1.0, -2.0])
    # (0.7 * 1 + 0.3 * 4) / 2 = 0.95
    assert expectile_loss(diff, 0.7).item() == pytest.approx(0.95)
    y = td_target(torch.tensor([0.0, 1.0]), torch.tensor([False, True]), 0.99, torch.tensor([2.0, 5.0]))
    assert y.tolist() == pytest.approx([1.98, 1.0])
    a, b = torch.nn.Linear(1, 1), torch.nn.Linear(1, 1)
    with torch.no_grad():
        a.weight.fill_(0.0), b.weight.fill_(1.0)
    polyak_update(a, b, 0.005)
    assert a.weight.item() == pytest.approx(0.005)
    with pytest.raises(ValueError, match="tau"):
        expectile_loss(diff, 1.0)
