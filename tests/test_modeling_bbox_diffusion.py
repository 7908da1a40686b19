"""The policy's sampling paths: the TorchScript-traced UNet and its ONNX Runtime session must give the eager
UNet's chunks."""

import sys

import numpy as np
import pytest
import torch

from lerobot_bboxpick.apps.bench import _policy_features
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy
from lerobot_bboxpick.policies.bbox_diffusion.onnx_runtime import convolutions_as_2d


def _policy(**overrides) -> BboxDiffusionPolicy:
    torch.manual_seed(0)
    inputs, outputs = _policy_features(image_size=96)
    config = BboxDiffusionConfig(device="cpu", input_features=inputs, output_features=outputs, **overrides)
    return BboxDiffusionPolicy(config).eval()


def _batch(b: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    return {
        "observation.images.wrist": torch.rand(b, 2, 3, 96, 96, generator=g),
        "observation.state": torch.rand(b, 2, 10, generator=g),
        "observation.bbox": torch.tensor([0.3, 0.3, 0.5, 0.6]).expand(b, 2, 4),
    }


def _chunk(policy: BboxDiffusionPolicy, batch: dict) -> torch.Tensor:
    return policy.predict_action_chunk(batch, generator=torch.Generator().manual_seed(7))


def test_traced_unet_gives_the_eager_chunk_and_follows_weight_updates():
    traced, eager = _policy(), _policy(jit_inference=False)
    batch = _batch(3)
    a, b = _chunk(traced, batch), _chunk(eager, batch)
    assert traced.ema_model._traced_unets, "jit_inference=True did not use a trace"
    assert not eager.ema_model._traced_unets
    assert (a - b).abs().max() < 1e-5
    assert a.abs().max() > 1e-3  # a real chunk, not zeros on both sides
    # In-place weight changes (what EMA updates and load_state_dict do) reach the existing trace.
    for policy in (traced, eager):
        with torch.no_grad():
            for p in policy.ema_model.unet.parameters():
                p.mul_(1.5)
    a2, b2 = _chunk(traced, batch), _chunk(eager, batch)
    assert (a2 - b2).abs().max() < 1e-5
    assert (a2 - a).abs().max() > 1e-3  # the update changed the prediction
    # A new batch size gets its own trace with the same numbers as eager.
    one = {k: v[:1] for k, v in batch.items()}
    assert (_chunk(traced, one) - _chunk(eager, one)).abs().max() < 1e-5
    assert len(traced.ema_model._traced_unets) == 2
    assert not any("traced" in k for k in traced.state_dict())  # the cache is not part of a checkpoint


def test_training_and_autocast_keep_the_eager_unet():
    policy = _policy(autocast_inference=True, onnx_inference=True)
    batch = _batch(2)
    policy.train()
    loss, _ = policy.forward({**batch, "action": torch.rand(2, 16, 10)})
    loss.backward()  # training goes through the eager UNet, so gradients reach its weights
    assert policy.model.unet.final_conv[-1].weight.grad.abs().sum() > 0
    policy.eval()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        _chunk(policy, batch)
    assert not policy.ema_model._traced_unets
    assert not policy.ema_model._onnx_sessions  # ONNX Runtime graphs are float32: autocast keeps PyTorch


def test_sampling_leaves_an_enclosing_autocast_by_default():
    """lerobot-eval samples under autocast for use_amp checkpoints; by default the policy samples in
    float32 through the trace anyway (same chunk as outside autocast), with autocast_inference it does not."""
    policy, batch = _policy(), _batch(2)
    plain = _chunk(policy, batch)
    policy.ema_model._traced_unets.clear()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        inside = _chunk(policy, batch)
    assert policy.ema_model._traced_unets, "sampling under autocast did not use the float32 trace"
    assert inside.dtype == torch.float32 and (inside - plain).abs().max() < 1e-6
    rounded = _policy(autocast_inference=True)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        bf16 = _chunk(rounded, batch)
    assert (bf16 - plain).abs().max() > 1e-4  # bf16 sampling really rounds: the switch does something


def test_autocast_keeps_pose_and_mask_conditioning_in_float32():
    """bf16 autocast (``--policy.use_amp=true``) may round the encoder features, never the poses."""
    policy = _policy()
    model = policy.model.eval()  # deterministic centre crop: both calls see the same pixels
    batch = _batch(2)
    # Valid poses 0.5 m from the base (identity rotation), the older one 1.3 mm further along x.
    pose = torch.tensor([0.5, 0.4, 0.3, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.05])
    batch["observation.state"] = pose.expand(2, 2, 10).clone()
    batch["observation.state"][:, 0, 0] += 0.0013
    inputs = model._inputs(batch)
    ref = model.global_condition(*inputs)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        amp = model.global_condition(*inputs)
    assert amp.dtype == torch.float32
    width = model.encoder.out_dim
    per_step = ref.view(2, 2, -1)
    lowdim_ref, lowdim_amp = per_step[..., width:], amp.view(2, 2, -1)[..., width:]
    assert (lowdim_amp - lowdim_ref).abs().max() < 1e-6
    # The scaled relative x of the older frame: 1.3 mm / obs_position_scale (0.02 m) = 0.065.
    assert abs(lowdim_ref[0, 0, 0].item() - 0.0013 / model.config.obs_position_scale) < 1e-4
    feats_ref, feats_amp = per_step[..., :width], amp.view(2, 2, -1)[..., :width]
    assert (feats_amp - feats_ref).abs().max() < 0.05 * feats_ref.abs().max()


def test_one_observed_step_trains_on_lerobot_dataset_shapes():
    """With n_obs_steps=1 LeRobotDataset squeezes the video frame's time axis but keeps the state's and
    the bbox's ((B, 3, H, W) beside (B, 1, 10)): the loss is the one of the explicit (B, 1, ...) batch."""
    policy = _policy(n_obs_steps=1, image_size=64).train()
    full = {k: v[:, -1:] for k, v in _batch(3).items()}
    full["action"] = torch.rand(3, 16, 10, generator=torch.Generator().manual_seed(2))
    squeezed = {**full, "observation.images.wrist": full["observation.images.wrist"][:, 0]}
    torch.manual_seed(5)
    expected = policy.forward(full)[0]
    torch.manual_seed(5)
    assert torch.allclose(policy.forward(squeezed)[0], expected)


def test_one_observed_step_reads_the_frames_own_row_with_the_windowed_loss(tmp_path):
    """With n_obs_steps=1 lerobot-train asks LeRobotDataset for no observation window (the loader's
    per-key window query is its main cost): the items hold the frame's own state, bbox and image, and
    the training loss equals the one of an explicit one-step window."""
    from helpers_data import make_expert_dataset
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from torch.utils.data import default_collate

    make_expert_dataset(tmp_path / "ds", [0])
    policy = _policy(n_obs_steps=1, image_size=64).train()
    assert policy.config.observation_delta_indices is None
    window = resolve_delta_timestamps(policy.config, LeRobotDataset("test/expert", root=tmp_path / "ds").meta)
    assert set(window) == {"action"}
    rowwise = LeRobotDataset("test/expert", root=tmp_path / "ds", delta_timestamps=window)
    explicit = LeRobotDataset(
        "test/expert",
        root=tmp_path / "ds",
        delta_timestamps={**window, **{k: [0.0] for k in ("observation.state", "observation.bbox")}},
    )
    frames = [5, 60, 120]
    a = default_collate([rowwise[i] for i in frames])
    b = default_collate([explicit[i] for i in frames])
    assert a["observation.state"].shape == (3, 10) and b["observation.state"].shape == (3, 1, 10)
    assert torch.equal(a["observation.state"], b["observation.state"][:, 0])
    assert torch.equal(a["observation.bbox"], b["observation.bbox"][:, 0])
    assert torch.equal(a["action"], b["action"])
    # The target moves over the episode: the rows differ, so equal tensors are not an accident.
    assert (a["observation.state"][0] - a["observation.state"][2]).abs().max() > 0.01
    torch.manual_seed(5)
    loss_a = policy.forward(a)[0]
    torch.manual_seed(5)
    assert torch.allclose(policy.forward(b)[0], loss_a)


def test_ema_update_moves_each_weight_by_one_minus_decay_towards_the_model():
    policy = _policy(use_ema=True, ema_power=0.75, ema_max_decay=0.9999)
    with torch.no_grad():
        for p in policy.model.parameters():
            p.add_(1.0)  # the model 1.0 away from its EMA copy on every weight
    before = [p.clone() for p in policy.ema_model.parameters()]
    policy.update()
    decay = 1 - 2**-0.75  # the first update: 1 - (1 + 1)^-power
    for ema_before, ema_after, p in zip(
        before, policy.ema_model.parameters(), policy.model.parameters(), strict=True
    ):
        expected = decay * ema_before + (1 - decay) * p
        assert torch.allclose(ema_after, expected, atol=1e-6)
    moved = [(a - b).abs().mean().item() for a, b in zip(policy.ema_model.parameters(), before, strict=True)]
    assert min(moved) > 0.594 and max(moved) < 0.595  # 1 - decay = 2^-0.75 = 0.5946 of the 1.0 gap


def test_optimizer_preset_is_fused_adamw_with_the_loop_implementations_steps():
    """The preset's fused AdamW (a CPU speed-up) takes the same steps as torch's default AdamW."""
    config = _policy().config
    preset = config.get_optimizer_preset()
    assert preset.type == "adamw_fused" and preset.lr == config.optimizer_lr
    results = []
    default_adamw = lambda groups: torch.optim.AdamW(groups, **_adamw_kwargs(preset))  # noqa: E731
    for build, fused in ((preset.build, True), (default_adamw, None)):
        policy = _policy().train()
        optimizer = build(policy.get_optim_params())
        assert optimizer.defaults["fused"] is fused
        g = torch.Generator().manual_seed(3)
        for _ in range(3):
            for p in policy.parameters():
                p.grad = torch.randn(p.shape, generator=g)
            optimizer.step()
        results.append(torch.cat([p.detach().flatten() for p in policy.parameters()]))
    fused, loop = results
    assert (fused - loop).abs().max().item() < 1e-6
    assert (fused - torch.cat([p.detach().flatten() for p in _policy().parameters()])).abs().max() > 1e-4


def test_timestep_spacing_picks_where_few_step_sampling_starts():
    """ "trailing" starts at the last training timestep whatever the step count; "leading" (the default,
    every published table) starts lower the fewer the steps; an unknown spacing names the field."""
    visited = {}
    for spacing in ("leading", "trailing"):
        policy = _policy(n_obs_steps=2, num_inference_steps=4, timestep_spacing=spacing)
        chunk = _chunk(policy, _batch(1))
        visited[spacing] = (policy.ema_model.noise_scheduler.timesteps.tolist(), chunk)
    assert visited["leading"][0] == [36, 24, 12, 0]
    assert visited["trailing"][0] == [49, 37, 24, 11]
    # Same weights and noise, a different path: the chunks differ (mm-scale positions, not rounding).
    assert (visited["leading"][1] - visited["trailing"][1]).abs().max().item() > 1e-3
    assert BboxDiffusionConfig().timestep_spacing == "leading"
    allowed = "timestep_spacing='cosine' is not one of leading, trailing, linspace"
    with pytest.raises(ValueError, match=allowed):
        BboxDiffusionConfig(timestep_spacing="cosine")


def test_a_setting_changed_on_a_live_policy_reaches_the_ema_model_that_samples():
    """The EMA model is a deep copy of the model; it must still read the policy's own config, or a step
    count set after construction (as the suite's --num_inference_steps does) would be ignored."""
    policy = _policy(n_obs_steps=2, num_inference_steps=8)
    first = _chunk(policy, _batch(1))
    assert len(policy.ema_model.noise_scheduler.timesteps) == 8
    policy.config.num_inference_steps = 3
    fewer = _chunk(policy, _batch(1))
    assert policy.ema_model.noise_scheduler.timesteps.tolist() == [32, 16, 0]
    assert (fewer - first).abs().max().item() > 1e-3  # a different sampler path, not the cached one
    assert policy.ema_model.config is policy.config is policy.model.config


def _adamw_kwargs(preset) -> dict:
    return {"lr": preset.lr, "betas": preset.betas, "eps": preset.eps, "weight_decay": preset.weight_decay}


def test_onnx_loop_gives_the_eager_chunk_and_follows_weight_updates():
    onnx, eager = _policy(onnx_inference=True), _policy(jit_inference=False)
    batch = _batch(2)
    a, b = _chunk(onnx, batch), _chunk(eager, batch)
    sessions = onnx.ema_model._onnx_sessions
    # One graph for the encoder (2 samples x 2 frames) and one for the whole 16-step loop at batch 2; no
    # per-call UNet session and no trace.
    assert list(sessions) == [
        ("encoder", (2, 2, 3, 96, 96)),
        ("loop", 2, "DDIMScheduler", 16),
    ]
    assert not onnx.ema_model._traced_unets
    assert a.abs().max() > 1e-3  # a real chunk, not zeros on both sides
    assert (a - b).abs().max() < 1e-4
    session = sessions[("encoder", (2, 2, 3, 96, 96))]
    assert _chunk(onnx, batch).equal(a)
    assert sessions[("encoder", (2, 2, 3, 96, 96))] is session  # reused, not re-exported
    # An in-place weight change (an EMA step, load_state_dict) makes the session stale: it is re-exported
    # and follows the new weights, as the eager UNet does.
    for policy in (onnx, eager):
        with torch.no_grad():
            for p in policy.ema_model.parameters():
                p.mul_(1.5)
    a2, b2 = _chunk(onnx, batch), _chunk(eager, batch)
    assert sessions[("encoder", (2, 2, 3, 96, 96))] is not session
    assert (a2 - a).abs().max() > 1e-3  # the update changed the prediction
    assert (a2 - b2).abs().max() < 1e-4
    # Another step count is another graph, again the eager sampler's chunk.
    for policy in (onnx, eager):
        policy.config.num_inference_steps = 4  # the EMA model that samples shares the policy's config
    assert (_chunk(onnx, batch) - _chunk(eager, batch)).abs().max() < 1e-4
    assert len(sessions) == 3
    assert not any("onnx" in k for k in onnx.state_dict())  # the sessions are not part of a checkpoint


def test_reset_in_eval_mode_exports_the_onnx_graphs_before_the_first_chunk():
    """LeRobot's rollout resets the policy before an episode: with onnx_inference the export happens
    there, and the episode's first chunk reuses those sessions (the same objects) with eager's numbers."""
    training = _policy(onnx_inference=True).train()
    training.reset()
    assert not training.ema_model._onnx_sessions  # train mode (as in __init__, before weights load): none
    onnx, eager = _policy(onnx_inference=True), _policy(jit_inference=False)
    before = torch.get_rng_state()
    onnx.reset()
    assert torch.get_rng_state().equal(before)  # its placeholder chunk draws its own noise
    sessions = dict(onnx.ema_model._onnx_sessions)
    assert [k[0] for k in sessions] == ["encoder", "loop"]
    assert not onnx._actions and not any(onnx._queues.values())  # the queues are left empty
    batch = {k: v[:, -1] for k, v in _batch(1).items()}  # one observation, as select_action receives it
    for policy in (onnx, eager):
        policy.reset()
        policy.select_action(batch, generator=torch.Generator().manual_seed(3))
    assert all(onnx.ema_model._onnx_sessions[k] is v for k, v in sessions.items())  # not exported again
    assert len(onnx.ema_model._onnx_sessions) == 2
    assert (onnx._actions[0] - eager._actions[0]).abs().max() < 1e-4


def test_reset_samples_no_placeholder_chunk_while_the_onnx_sessions_are_current(monkeypatch):
    """Once the sessions exist, an episode's reset costs nothing; a new step count (a new loop graph) or
    changed weights (stale sessions) make the next reset warm up again."""
    onnx = _policy(onnx_inference=True)
    onnx.reset()
    chunks = []
    original = type(onnx.ema_model).sample
    monkeypatch.setattr(
        type(onnx.ema_model), "sample", lambda self, *a, **k: chunks.append(1) or original(self, *a, **k)
    )
    onnx.reset()
    assert chunks == []
    onnx.config.num_inference_steps = 3
    onnx.reset()
    assert chunks == [1] and len(onnx.ema_model._onnx_sessions) == 3  # the 3-step loop beside the old one
    onnx.reset()
    assert chunks == [1]
    with torch.no_grad():
        next(onnx.ema_model.unet.parameters()).mul_(1.01)  # as an EMA update or a loaded state dict would
    onnx.reset()
    assert chunks == [1, 1] and onnx.ema_model.has_current_onnx_sessions(1)
    onnx.reset()  # the 16-step loop left stale beside them is not the one the next chunk uses
    assert chunks == [1, 1]


def test_convolutions_as_2d_compute_the_same_and_restore_the_module():
    """The export's 1-D -> 2-D convolution swap (ONNX Runtime's fast CPU kernels are 2-D only) computes the
    same numbers for strided, padded, dilated, grouped and transposed convolutions, and undoes itself."""
    torch.manual_seed(0)
    net = torch.nn.Sequential(
        torch.nn.Conv1d(8, 16, 5, padding=2),
        torch.nn.Conv1d(16, 16, 3, stride=2, padding=2, dilation=2, groups=4),
        torch.nn.ConvTranspose1d(16, 8, 4, stride=2, padding=1),
        torch.nn.Conv1d(8, 8, 3, padding=1, padding_mode="circular"),  # not zero-padded: kept as it is
    )
    x = torch.randn(3, 8, 16)
    before = net(x)
    with convolutions_as_2d(net):
        assert [type(m).__name__ for m in net] == ["_Conv1dAs2d"] * 3 + ["Conv1d"]
        assert (net(x) - before).abs().max() < 1e-5
        assert before.abs().max() > 0.1
    assert [type(m) for m in net] == [
        torch.nn.Conv1d,
        torch.nn.Conv1d,
        torch.nn.ConvTranspose1d,
        torch.nn.Conv1d,
    ]
    assert net(x).equal(before)


def test_onnx_loop_keeps_dpm_solver_history_per_chunk():
    """DPM-Solver++ steps with the previous outputs; exporting steps the scheduler, so its history must be
    cleared again before the graph's chunk, and two chunks in a row must each match eager's."""
    onnx = _policy(onnx_inference=True, sampler="dpmsolver++", num_inference_steps=6)
    eager = _policy(jit_inference=False, sampler="dpmsolver++", num_inference_steps=6)
    batch = _batch(1)
    for _ in range(2):
        assert (_chunk(onnx, batch) - _chunk(eager, batch)).abs().max() < 1e-4
    loops = [k for k in onnx.ema_model._onnx_sessions if k[0] == "loop"]
    assert [k[2] for k in loops] == ["DPMSolverMultistepScheduler"]


def test_onnx_guided_sampling_runs_each_unet_call_as_a_graph():
    """A guide is Python, so a guided chunk runs the loop here with one UNet session, as eager does."""
    onnx = _policy(onnx_inference=True, prediction_type="sample")
    eager = _policy(jit_inference=False, prediction_type="sample")
    batch = _batch(2)

    def guide(clean: torch.Tensor) -> torch.Tensor:
        return 0.1 * torch.tanh(clean)  # any correction the loop must apply at every step

    chunks = [p.predict_action_chunk(batch, torch.Generator().manual_seed(3), guide) for p in (onnx, eager)]
    assert [k for k in onnx.ema_model._onnx_sessions if k[0] != "encoder"] == [("unet", 2)]
    assert (chunks[0] - chunks[1]).abs().max() < 1e-4
    unguided = eager.predict_action_chunk(batch, torch.Generator().manual_seed(3))
    assert (chunks[1] - unguided).abs().max() > 1e-3  # the guide moved the chunk


def test_onnx_inference_without_onnxruntime_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # what a plain install without the extra sees
    with pytest.raises(ImportError, match=r"pip install 'lerobot_bboxpick\[onnx\]'"):
        _chunk(_policy(onnx_inference=True), _batch(1))


def _training_timesteps(policy: BboxDiffusionPolicy, b: int) -> set[int]:
    """The timesteps one training step asks the UNet about (its second positional argument)."""
    seen: list[torch.Tensor] = []
    hook = policy.model.unet.register_forward_pre_hook(lambda _, args: seen.append(args[1].clone()))
    policy.train()
    policy.forward({**_batch(b), "action": torch.rand(b, 16, 10)})
    hook.remove()
    return {int(t) for t in torch.cat(seen)}


def test_train_on_sampler_timesteps_trains_only_where_ddim_samples():
    """With six leading DDIM steps of 50, the sampler visits 40, 32, 24, 16, 8 and 0: a model trained for
    that sampler is asked about those noise levels only; by default about all 50."""
    few = _policy(num_inference_steps=6, train_on_sampler_timesteps=True)
    assert few.model.sampler_timesteps().tolist() == [40, 32, 24, 16, 8, 0]
    assert _training_timesteps(few, 64) == {40, 32, 24, 16, 8, 0}  # 64 draws hit all six (p > 0.99)
    assert len(_training_timesteps(_policy(num_inference_steps=6), 64) - {40, 32, 24, 16, 8, 0}) > 20


def test_rotation_scale_magnifies_a_turn_around_the_identity_and_round_trips():
    from scipy.spatial.transform import Rotation

    from lerobot_bboxpick.geometry import mat_to_rot6d
    from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import PoseScaler

    turn = torch.zeros(2, 10)
    turn[:, 3:9] = torch.tensor(
        np.stack(
            [mat_to_rot6d(np.eye(3)), mat_to_rot6d(Rotation.from_euler("z", 20, degrees=True).as_matrix())]
        )
    )
    turn[:, :3] = 0.03
    turn[:, 9] = 0.02
    unscaled, magnified = PoseScaler(0.15, 0.09), PoseScaler(0.15, 0.09, rotation_scale=0.36)
    # 1.0 is the published behaviour: rot6d entries pass through untouched
    assert torch.equal(unscaled(turn)[:, 3:9], turn[:, 3:9])
    scaled = magnified(turn)
    assert torch.allclose(scaled[0, 3:9], turn[0, 3:9])  # no turn stays the identity
    sin20 = np.sin(np.radians(20))
    assert abs(abs(float(scaled[1, 4])) - sin20 / 0.36) < 1e-5  # a 20-degree turn's yaw entry: 0.95
    assert torch.allclose(scaled[:, :3], unscaled(turn)[:, :3]) and torch.allclose(
        scaled[:, 9], unscaled(turn)[:, 9]
    )
    assert torch.allclose(magnified.inverse(scaled), turn, atol=1e-6)


@pytest.mark.parametrize("value", [0.0, -0.3, 1.5])
def test_a_rotation_scale_outside_zero_one_names_the_field(value: float):
    with pytest.raises(ValueError, match=r"action_rotation_scale=.* must be in \(0, 1\]"):
        BboxDiffusionConfig(action_rotation_scale=value)
