"""Progressive step distillation: the teacher's batched DDIM steps are diffusers' own, the student's target
lands where the teacher's two steps land, and training on it brings the student's n-step chunks to the
teacher's 2n-step ones."""

import copy

import pytest
import torch
from diffusers.schedulers.scheduling_ddim import DDIMScheduler

from lerobot_bboxpick.apps.bench import _policy_features
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy
from lerobot_bboxpick.policies.bbox_diffusion.step_distillation import (
    FINAL,
    StepDistillationLoss,
    ddim_step,
    one_step_target,
    step_pairs,
)

SMALL = dict(backbone="resnet10t", image_size=64, down_dims=(32, 64), diffusion_step_embed_dim=32)


def _policy(**overrides) -> BboxDiffusionPolicy:
    torch.manual_seed(0)
    inputs, outputs = _policy_features(image_size=64)
    config = BboxDiffusionConfig(
        device="cpu", input_features=inputs, output_features=outputs, n_obs_steps=1, **SMALL, **overrides
    )
    return BboxDiffusionPolicy(config)


def _batch(b: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    state = torch.zeros(b, 1, 10)
    state[..., 2] = 0.3
    state[..., 3] = state[..., 7] = 1.0  # identity rotation (6D), gripper 0
    return {
        "observation.images.wrist": torch.rand(b, 1, 3, 64, 64, generator=g),
        "observation.state": state,
        "observation.bbox": torch.tensor([0.3, 0.3, 0.5, 0.6]).expand(b, 1, 4),
        "action": state.expand(b, 16, 10)
        + 0.02 * torch.randn(b, 16, 10, generator=g) * (torch.arange(10) < 3),
    }


@pytest.mark.parametrize("prediction_type", ["sample", "epsilon"])
def test_batched_ddim_step_is_diffusers_step_at_every_timestep(prediction_type):
    model = _policy(prediction_type=prediction_type, num_inference_steps=8).model
    scheduler = DDIMScheduler.from_config(model.noise_scheduler.config)
    scheduler.set_timesteps(8)
    visited = scheduler.timesteps.tolist()
    g = torch.Generator().manual_seed(3)
    noisy = torch.randn(len(visited), 16, 10, generator=g)
    output = 1.5 * torch.randn(len(visited), 16, 10, generator=g)  # some beyond the clip range
    starts = torch.tensor(visited)
    ends = torch.tensor(visited[1:] + [FINAL])
    batched = ddim_step(model, output, noisy, starts, ends)
    for i, t in enumerate(visited):
        expected = scheduler.step(output[i : i + 1], t, noisy[i : i + 1]).prev_sample
        assert (batched[i] - expected[0]).abs().max() < 1e-5, t


@pytest.mark.parametrize("prediction_type", ["sample", "epsilon"])
def test_one_step_target_lands_where_it_was_aimed(prediction_type):
    model = _policy(prediction_type=prediction_type).model
    g = torch.Generator().manual_seed(4)
    starts, ends = torch.tensor([42, 36, 12, 0]), torch.tensor([36, 30, 6, FINAL])
    noisy = torch.randn(4, 16, 10, generator=g)
    # An aim that one step can reach: where some in-range clean chunk lands.
    reachable = ddim_step(model, torch.rand(4, 16, 10, generator=g) * 1.6 - 0.8, noisy, starts, ends)
    if prediction_type == "epsilon":  # an epsilon output of that chunk
        reachable = ddim_step(
            model, one_step_target(model, noisy, reachable, starts, ends), noisy, starts, ends
        )
    target = one_step_target(model, noisy, reachable, starts, ends)
    assert (ddim_step(model, target, noisy, starts, ends) - reachable).abs().max() < 1e-4


def test_student_steps_pair_with_the_teachers_two_and_mismatches_are_refused():
    teacher = _policy(num_inference_steps=16).model
    pairs = step_pairs(_policy(num_inference_steps=8).model, teacher)
    assert pairs.start.tolist() == [42, 36, 30, 24, 18, 12, 6, 0]
    assert pairs.middle.tolist() == [39, 33, 27, 21, 15, 9, 3, FINAL]
    assert pairs.end.tolist() == [36, 30, 24, 18, 12, 6, 0, FINAL]
    with pytest.raises(ValueError, match="num_inference_steps=7"):
        step_pairs(_policy(num_inference_steps=7).model, teacher)


def test_the_config_refuses_distillation_beside_another_objective():
    with pytest.raises(ValueError, match="distill_teacher_path"):
        _policy(distill_teacher_path="a", anchor_policy_path="b")
    with pytest.raises(ValueError, match="sampler='ddim'"):
        _policy(distill_teacher_path="a", sampler="dpmsolver++")


@torch.no_grad()
def _landing_gap(student, teacher, batch: dict, pairs) -> float:
    """Mean squared gap between where the student's one DDIM step and the teacher's two land, from the
    batch's chunks freshly noised at every student timestep (eval mode: no augmentation)."""
    student.eval(), teacher.eval()
    cond, chunk, teacher_cond = student.conditioned_chunk(batch, teacher)
    g = torch.Generator().manual_seed(9)
    gaps = []
    for start, middle, end in zip(pairs.start, pairs.middle, pairs.end, strict=True):
        b = cond.shape[0]
        s, m, e = (torch.full((b,), int(t)) for t in (start, middle, end))
        noisy = student.noise_scheduler.add_noise(chunk, torch.randn(b, 16, 10, generator=g), s)
        halfway = ddim_step(teacher, teacher.unet(noisy, s, global_cond=teacher_cond), noisy, s, m)
        landed = (
            halfway
            if int(middle) == FINAL
            else ddim_step(teacher, teacher.unet(halfway, m, global_cond=teacher_cond), halfway, m, e)
        )
        one_step = ddim_step(student, student.unet(noisy, s, global_cond=cond), noisy, s, e)
        gaps.append((one_step - landed).pow(2).mean().item())
    return sum(gaps) / len(gaps)


def test_distillation_brings_the_students_one_step_to_where_the_teachers_two_land():
    """The student (initialised as the teacher, sampling in half its steps) trained on the loss: from
    noisings it never trained on, its one step lands at least twice as close to the teacher's two (about
    9x here)."""
    teacher_policy = _policy(num_inference_steps=8, jit_inference=False)
    student = copy.deepcopy(teacher_policy)
    student.config.num_inference_steps = 4
    loss_fn = StepDistillationLoss(copy.deepcopy(teacher_policy.model))
    pairs = step_pairs(student.model, loss_fn.teacher)
    batch = _batch(8)
    before = _landing_gap(student.model, loss_fn.teacher, batch, pairs)
    optimiser = torch.optim.Adam(student.model.unet.parameters(), lr=1e-4)
    torch.manual_seed(6)
    for _ in range(100):
        student.model.train()
        loss, _ = loss_fn(student.model, batch)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    after = _landing_gap(student.model, loss_fn.teacher, batch, pairs)
    assert after < 0.5 * before, (before, after)
