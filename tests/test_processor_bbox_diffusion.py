"""UMI relative SE(3) poses (geometry) and the bbox_diffusion processors (stateless, saved with
the checkpoint)."""

import numpy as np
import torch
from lerobot.configs import FeatureType, PolicyFeature
from scipy.spatial.transform import Rotation

from lerobot_bboxpick import geometry
from lerobot_bboxpick.geometry import absolute_pose10_torch, relative_pose10_torch


def _random_pose10(n: int, seed: int) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    T[:, :3, 3] = rng.uniform(-0.5, 0.8, size=(n, 3))
    width = rng.uniform(0, 0.09, size=(n, 1))
    return torch.tensor(np.concatenate([geometry.mat_to_pose9(T), width], axis=1), dtype=torch.float32)


def test_absolute_relative_absolute_round_trip_within_1e5():
    base = _random_pose10(4, 0)  # (B, 10) latest observed poses
    chunk = _random_pose10(4 * 16, 1).view(4, 16, 10)
    rel = relative_pose10_torch(chunk, base)
    assert not torch.allclose(rel, chunk)
    # The relative pose of the base itself is the identity, and the width stays absolute.
    ident = relative_pose10_torch(base[:, None], base)[:, 0]
    assert torch.allclose(ident[:, :9], torch.tensor(geometry.IDENTITY_POSE9, dtype=torch.float32), atol=1e-6)
    assert torch.equal(rel[..., 9], chunk[..., 9])
    back = absolute_pose10_torch(rel, base)
    assert (back - chunk).abs().max() < 1e-5


def test_relative_position_is_expressed_in_the_base_frame():
    # Base: top-down gripper at (0.5, 0, 0.2); the target 10 cm lower in the table frame is 10 cm
    # along the gripper's approach axis (+z of the gripper frame).
    R = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = [0.5, 0.0, 0.2]
    base = torch.tensor(np.r_[geometry.mat_to_pose9(T), 0.05], dtype=torch.float32)[None]
    T[:3, 3] = [0.5, 0.0, 0.1]
    target = torch.tensor(np.r_[geometry.mat_to_pose9(T), 0.0], dtype=torch.float32)[None, None]
    rel = relative_pose10_torch(target, base)
    assert torch.allclose(rel[0, 0, :3], torch.tensor([0.0, 0.0, 0.1]), atol=1e-6)
    assert torch.allclose(absolute_pose10_torch(rel, base), target, atol=1e-6)


def test_saved_pipelines_pass_absolute_actions_through(tmp_path):
    """The processors hold no pose state: after save/load the postprocessor returns the policy's
    absolute action unchanged, and the preprocessor leaves the observed pose as it was."""
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action

    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
    from lerobot_bboxpick.policies.bbox_diffusion.processor_bbox_diffusion import (
        make_bbox_diffusion_pre_post_processors,
    )

    pre, post = make_bbox_diffusion_pre_post_processors(BboxDiffusionConfig(device="cpu"))
    pre.save_pretrained(tmp_path)
    post.save_pretrained(tmp_path)
    pre2 = PolicyProcessorPipeline.from_pretrained(tmp_path, config_filename="policy_preprocessor.json")
    post2 = PolicyProcessorPipeline.from_pretrained(
        tmp_path,
        config_filename="policy_postprocessor.json",
        to_transition=policy_action_to_transition,
        to_output=transition_to_policy_action,
    )
    state = _random_pose10(1, 5)
    assert torch.equal(pre2({"observation.state": state})["observation.state"], state)
    action = _random_pose10(1, 6)
    assert torch.equal(post2(action), action)


def test_a_robot_packed_state_is_split_into_pose_and_bbox():
    """lerobot-record / lerobot-rollout pack the ur5's 14 scalars into observation.state: the step splits
    them (pose10, then the box) and leaves the env's separate keys alone."""
    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
    from lerobot_bboxpick.policies.bbox_diffusion.processor_bbox_diffusion import UnpackBboxFromStateStep

    step = UnpackBboxFromStateStep()
    packed = torch.arange(2 * 3 * 14, dtype=torch.float32).reshape(2, 3, 14)
    out = step.observation({"observation.state": packed})
    assert torch.equal(out["observation.state"], packed[..., :10])
    assert torch.equal(out["observation.bbox"], packed[..., 10:])
    separate = {"observation.state": packed[..., :10], "observation.bbox": torch.ones(2, 3, 4)}
    out = step.observation(dict(separate))
    assert torch.equal(out["observation.bbox"], torch.ones(2, 3, 4))
    # The config reads a packed 14-float state feature as pose10 + bbox.
    cfg = BboxDiffusionConfig(
        input_features={
            "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(14,)),
            "observation.images.wrist": PolicyFeature(type=FeatureType.VISUAL, shape=(3, 224, 224)),
        },
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(10,))},
    )
    cfg.validate_features()
    assert cfg.input_features["observation.state"].shape == (10,)
    assert cfg.input_features["observation.bbox"].shape == (4,)
