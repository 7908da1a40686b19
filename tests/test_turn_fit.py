"""``lerobot_bboxpick turn-fit``: teacher forcing on a real expert dataset; a policy that replays the demo's
chunk reproduces its whole turn, one that holds the observed pose none of it."""

import numpy as np
import pytest
from helpers_data import make_expert_dataset
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_bboxpick.eval.turn_fit import chunk_turns, turn_summary, yaw_change_deg
from lerobot_bboxpick.geometry import mat_to_pose9

TURNED_SEED = 5001  # random_id scene whose target is turned 44 degrees from the start gripper


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    root = tmp_path_factory.mktemp("turn_fit") / "data"
    make_expert_dataset(root, [TURNED_SEED], setting="random_id", repo_id="test/turn_fit")
    return LeRobotDataset(
        "test/turn_fit", root=root, delta_timestamps={"action": [i / 20 for i in range(16)]}
    )


def test_yaw_change_is_signed_and_wrapped():
    from scipy.spatial.transform import Rotation

    def pose10(deg: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("z", deg, degrees=True).as_matrix()
        return np.concatenate([mat_to_pose9(T), [0.0]])

    assert yaw_change_deg(pose10(30), pose10(10)) == pytest.approx(20)
    assert yaw_change_deg(pose10(-170), pose10(170)) == pytest.approx(20)


def test_replaying_the_demo_reproduces_its_turn_and_holding_still_none(demos):
    replay = chunk_turns(lambda item: item["action"].numpy(), demos, ["random_id"], [0, 16, 32])
    hold = chunk_turns(
        lambda item: np.repeat(item["observation.state"].numpy()[None], 16, 0), demos, ["random_id"], [0, 16]
    )
    # the expert turns onto the 44-degree brick on the way: its chunk from 0.8 s in turns well over 3 degrees
    assert abs(replay[1].demo_deg) > 10
    assert all(t.policy_deg == pytest.approx(t.demo_deg, abs=1e-3) for t in replay)
    assert all(abs(t.policy_deg) < 1e-3 for t in hold)
    assert "| all | 3 | " in turn_summary(replay) and "| 1.00 | 1.00 |" in turn_summary(replay)
    assert "| 0.00 |" in turn_summary(hold)
    # settings it has no demos of give no rows; unknown ones name the allowed values
    assert chunk_turns(lambda item: item["action"].numpy(), demos, ["grid_id"], [0]) == []
    with pytest.raises(
        ValueError, match="setting='grid' is not a lego_pick setting; valid settings: grid_id, "
    ):
        chunk_turns(lambda item: item["action"].numpy(), demos, ["grid"], [0])


def test_turn_fit_cli_runs_the_shipped_checkpoint_on_the_demos(demos, tmp_path, capsys):
    from lerobot_bboxpick.apps.cli import main
    from lerobot_bboxpick.shipped_checkpoints import SHIPPED_CHECKPOINT

    out = tmp_path / "turn.md"
    command = ["turn-fit", "--policy", str(SHIPPED_CHECKPOINT), "--dataset", str(demos.root)]
    main([*command, "--settings", "random_id", "--frames", "0,16,32", "--out", str(out)])
    rows = {line.split("|")[1].strip(): line.split("|")[2:-1] for line in out.read_text().splitlines()[2:]}
    assert set(rows) == {"0", "16", "32", "all"} and rows["all"][0].strip() == "3"
    assert 0.0 <= float(rows["all"][4]) < 45.0  # the policy's mean |turn| over a chunk, degrees
    assert out.read_text() in capsys.readouterr().out
    with pytest.raises(SystemExit):  # argparse names the allowed settings
        main([*command, "--settings", "grid"])
