"""The ``bbox_diffusion`` policy: UMI's diffusion policy with the target bbox as an image mask channel.

Data flow for one prediction (paper figure 5):
  wrist images (n_obs x 3 x 224 x 224) + bbox -> mask channel built at full resolution
  -> paired crop/resize (+ colour jitter on RGB) -> RGB+mask backbone -> one feature per frame
  observed TCP poses -> relative to the latest one (SE(3)) -> scaled low-dim vector
  [features, low-dim] of every observed step -> global condition (computed once per chunk)
  -> 16 DDIM steps of LeRobot's conditional 1-D UNet -> relative action chunk (pose10)
  -> composed with the latest observed pose -> absolute action chunk
The policy takes and returns absolute poses; the relative form (UMI) exists only inside the model.
"""

import logging
import time
import warnings
from collections import deque
from collections.abc import Callable
from copy import deepcopy
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from diffusers.schedulers.scheduling_ddim import DDIMScheduler
from diffusers.schedulers.scheduling_dpmsolver_multistep import DPMSolverMultistepScheduler
from lerobot.policies.diffusion.modeling_diffusion import DiffusionConditionalUnet1d
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import populate_queues
from lerobot.utils.constants import ACTION, OBS_STATE
from torch import Tensor, nn

from lerobot_bboxpick.geometry import (
    IDENTITY_POSE9,
    absolute_pose10_torch,
    mat_to_pose9,
    relative_pose10_torch,
)
from lerobot_bboxpick.latency import fresh_steps, observation_time
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
    POSE_DIM,
    BboxDiffusionConfig,
    BboxDiffusionPaperConfig,
)
from lerobot_bboxpick.policies.bbox_diffusion.encoder import (
    MaskedImageEncoder,
    PairedAugment,
    bbox_to_mask,
    mask_moments,
    mask_moments_dim,
)
from lerobot_bboxpick.policies.bbox_diffusion.onnx_runtime import OnnxModule
from lerobot_bboxpick.policies.bbox_diffusion.target_crop import TargetView

log = logging.getLogger(__name__)


# ``predicted clean chunk (B, horizon, 10), scaled -> correction of the same shape``: steers sampling.
Guide = Callable[[Tensor], Tensor]


class PoseScaler(nn.Module):
    """Fixed affine scaling of relative pose10 vectors into roughly [-1, 1] (and back).

    Positions are divided by a scale in metres, gripper widths map [0, max_width] to [-1, 1]. Rot6d
    entries are already in [-1, 1] (UMI leaves them unnormalised too); ``rotation_scale`` < 1 magnifies
    their departure from the identity (identity + (R - identity) / rotation_scale), so small turns are not
    lost in the sampler's noise while no turn stays exactly the identity. Fixed rather than fitted to
    dataset statistics because LeRobot hands the processors statistics of absolute poses only.
    """

    def __init__(self, position_scale: float, max_width: float, rotation_scale: float = 1.0) -> None:
        super().__init__()
        scale = torch.ones(10)
        scale[:3] = position_scale
        scale[3:9] = rotation_scale
        scale[9] = max_width / 2
        offset = torch.zeros(10)
        # (x - offset) / scale = identity + (x - identity) / scale  <=>  offset = identity * (1 - scale)
        offset[3:9] = torch.from_numpy(IDENTITY_POSE9[3:]).float() * (1.0 - rotation_scale)
        offset[9] = max_width / 2
        self.register_buffer("scale", scale, persistent=False)
        self.register_buffer("offset", offset, persistent=False)

    def forward(self, pose10: Tensor) -> Tensor:
        """Scale."""
        return (pose10 - self.offset) / self.scale

    def inverse(self, scaled: Tensor) -> Tensor:
        """Unscale."""
        return scaled * self.scale + self.offset


@dataclass
class DenoisingTerms:
    """One training draw's per-sample denoising losses (B,) and predictions (B, horizon, 10)."""

    loss: Tensor
    prediction: Tensor
    reference_prediction: Tensor | None = None


def _rng_states(devices: list[torch.device]) -> list[Tensor]:
    return [torch.get_rng_state()] + [torch.cuda.get_rng_state(d) for d in devices]


def _set_rng_states(states: list[Tensor], devices: list[torch.device]) -> None:
    torch.set_rng_state(states[0])
    for state, device in zip(states[1:], devices, strict=True):
        torch.cuda.set_rng_state(state, device)


def global_condition_dim(config: BboxDiffusionConfig, image_feature_dim: int) -> int:
    """Width of the UNet's global condition: per observed step, the image feature, the scaled pose10,
    (with ``lowdim`` bbox mode: the 4 box numbers; with the mask centroid: its 4 or 5) and
    (``height_input``) the height."""
    box = 4 if config.bbox_mode == "lowdim" else 0
    if config.mask_centroid:
        box = mask_moments_dim(config.mask_size_scale)
    lowdim = POSE_DIM + box + int(config.height_input)
    return config.n_obs_steps * (image_feature_dim + lowdim)


def backbone_options(config: BboxDiffusionConfig) -> dict:
    """``MaskedImageEncoder`` keywords of the policy's architecture, shared by the main encoder and the
    target view's (which differ in image size and mask channel only)."""
    return {
        "backbone": config.backbone,
        "pretrained": config.pretrained_backbone,
        "pooling": config.pooling,
        "feature_stage": config.feature_stage,
        "num_keypoints": config.num_keypoints,
        "group_norm": config.group_norm,
    }


def build_target_view(config: BboxDiffusionConfig) -> TargetView | None:
    """The target view of ``config`` (``target_crop_size`` > 0), else None."""
    if not config.target_crop_size:
        return None
    return TargetView(
        config.target_crop_size,
        config.target_crop_context,
        config.target_crop_min_side,
        backbone_options(config),
        color_jitter=config.color_jitter,
    )


def image_feature_dim(module: nn.Module) -> int:
    """Image features per observed step of a module holding ``encoder`` and ``target_view`` (the model,
    or the critic's copy of its observation path)."""
    return module.encoder.out_dim + (module.target_view.out_dim if module.target_view is not None else 0)


def sampling_scheduler(
    config: BboxDiffusionConfig, ddim: DDIMScheduler
) -> DDIMScheduler | DPMSolverMultistepScheduler:
    """The scheduler ``sample`` steps with (``config.sampler``): ``ddim`` itself, or DPM-Solver++ on the
    same noise schedule, whose per-chunk history ``set_timesteps`` clears."""
    if config.sampler == "ddim":
        return ddim
    return DPMSolverMultistepScheduler.from_config(  # DDIM's noise schedule and prediction type
        ddim.config,
        algorithm_type="dpmsolver++",
        solver_order=2,
        lower_order_final=True,  # first order on the last step: stable at few steps (diffusers' advice)
    )


class BboxDiffusionModel(nn.Module):
    """Observation encoder (+ target view) + conditional UNet + DDIM scheduler."""

    def __init__(self, config: BboxDiffusionConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = MaskedImageEncoder(
            image_size=config.image_size, use_mask=config.bbox_mode == "mask", **backbone_options(config)
        )
        self.target_view = build_target_view(config)
        self.augment = PairedAugment(crop_ratio=config.crop_ratio, color_jitter=config.color_jitter)
        self.obs_scaler = PoseScaler(config.obs_position_scale, config.max_gripper_width)
        self.action_scaler = PoseScaler(
            config.action_position_scale, config.max_gripper_width, config.action_rotation_scale
        )
        self.unet = DiffusionConditionalUnet1d(
            config, global_cond_dim=global_condition_dim(config, image_feature_dim(self))
        )
        self.noise_scheduler = DDIMScheduler(
            num_train_timesteps=config.num_train_timesteps,
            beta_start=config.beta_start,
            beta_end=config.beta_end,
            beta_schedule=config.beta_schedule,
            clip_sample=config.clip_sample,
            clip_sample_range=config.clip_sample_range,
            set_alpha_to_one=True,
            steps_offset=0,
            prediction_type=config.prediction_type,
            timestep_spacing=config.timestep_spacing,
        )
        self.sampling_scheduler = sampling_scheduler(config, self.noise_scheduler)
        # TorchScript traces of the UNet by (device, dtype, batch) and ONNX Runtime sessions (of the
        # UNet, or of the whole denoising loop at its timesteps) by what they were exported for, built on
        # first use (see sample). Plain dicts, not submodules: nothing extra in the state dict.
        self._traced_unets: dict[tuple, torch.jit.ScriptModule] = {}
        self._onnx_sessions: dict[tuple, OnnxModule] = {}

    def global_condition(self, images: Tensor, states: Tensor, bboxes: Tensor | None) -> Tensor:
        """(B, T, 3, H, W) images in [0,1], (B, T, 10) absolute poses, (B, T, 4) bboxes -> (B, cond)."""
        b, t = states.shape[:2]
        # Under autocast (``--policy.use_amp=true``) only the encoder and the UNet run in reduced
        # precision: bf16 matmuls would round the millimetre-scale relative poses of 0.5 m absolute ones
        # and blur the mask resampling, so that part stays float32.
        with torch.autocast(states.device.type, enabled=False):
            states = states.float()
            rel_states = relative_pose10_torch(states, states[:, -1])
            lowdim = [self.obs_scaler(rel_states)]
            if self.config.height_input:
                lowdim.append((states[..., 2:3] - self.config.table_height) / self.config.height_input_scale)
            mask = None
            if self.config.bbox_mode == "mask":
                # The mask is drawn at the camera resolution before any crop/resize, so augmentation
                # moves it with the pixels it marks.
                mask = bbox_to_mask(bboxes.float(), images.shape[-2], images.shape[-1])
            elif self.config.bbox_mode == "lowdim":
                lowdim.append(bboxes.float() * 2 - 1)
            # One crop window per sample, shared by its observed frames.
            rgb, mask = self.augment(images.float(), mask, out_size=self.config.image_size)
            if self.config.mask_centroid:  # measured after the crop: consistent with the pixels
                lowdim.append(mask_moments(mask, self.config.mask_size_scale))
        features = self.encode_images(rgb, mask).view(b, t, -1).float()
        if self.target_view is not None:  # the raw frames: the window is cut before any crop or resize
            features = torch.cat([features, self.target_view(images, bboxes).view(b, t, -1).float()], dim=-1)
        return torch.cat([features, *lowdim], dim=-1).flatten(1)

    def encode_images(self, rgb: Tensor, mask: Tensor | None) -> Tensor:
        """The main encoder's features: in eval mode on a CPU with ``onnx_inference``, its ONNX Runtime
        session (the same numbers; the backbone's per-op dispatch is most of its time at 64 px)."""
        eager = self.training or rgb.device.type != "cpu" or torch.is_autocast_enabled("cpu")
        if not self.config.onnx_inference or eager:
            return self.encoder(rgb, mask)
        inputs = {"rgb": rgb} if mask is None or not self.encoder.use_mask else {"rgb": rgb, "mask": mask}
        session = self._onnx_session(("encoder", tuple(rgb.shape)), lambda: self.encoder, inputs)
        return session(*inputs.values())

    def backbone_parameters(self) -> list[nn.Parameter]:
        """Parameters of the image backbones (the main encoder's and the target view's)."""
        params = list(self.encoder.backbone_parameters())
        if self.target_view is not None:
            params += self.target_view.encoder.backbone_parameters()
        return params

    def _inputs(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor, Tensor | None]:
        images = batch[self.config.image_key]
        states = batch[OBS_STATE]
        bboxes = batch.get(self.config.bbox_feature_key)
        # A single step without a time axis, per tensor: with one observed step (n_obs_steps=1)
        # LeRobotDataset squeezes the video frame's time axis but keeps the state's and the bbox's.
        if images.ndim == 4:
            images = images[:, None]
        if states.ndim == 2:
            states = states[:, None]
        if bboxes is not None and bboxes.ndim == 2:
            bboxes = bboxes[:, None]
        return images, states, bboxes

    def compute_loss(self, batch: dict[str, Tensor]) -> Tensor:
        """Denoising loss with UMI's input perturbation on the chunk ``batch[ACTION]`` (absolute poses),
        made relative to the latest observed pose first."""
        return self.denoising_terms(batch).loss.mean()

    def conditioned_chunk(
        self, batch: dict[str, Tensor], reference: "BboxDiffusionModel | None" = None
    ) -> tuple[Tensor, Tensor, Tensor | None]:
        """One training draw's global condition (augmented observation), the batch's action chunk
        (relative to the latest observed pose, scaled), and, given a frozen ``reference`` model of the
        same architecture, its condition of the same crop and colour jitter (its augmentation replays
        this model's random draws)."""
        images, states, bboxes = self._inputs(batch)
        devices = [states.device] if states.device.type == "cuda" else []
        augmentation_draws = _rng_states(devices)  # where this model's crop and jitter draws start
        cond = self.global_condition(images, states, bboxes)
        reference_cond = None
        if reference is not None:
            # Replaying the augmentation's draws gives the reference the same crop and jitter; the fork
            # puts the generators back where this model's draws left them.
            with torch.no_grad(), torch.random.fork_rng(devices=devices):
                _set_rng_states(augmentation_draws, devices)
                reference_cond = reference.global_condition(images, states, bboxes)
        with torch.autocast(states.device.type, enabled=False):  # millimetres of 0.5 m poses: float32
            relative = relative_pose10_torch(batch[ACTION].float(), states[:, -1].float())
        return cond, self.action_scaler(relative), reference_cond

    def denoising_terms(
        self, batch: dict[str, Tensor], reference: "BboxDiffusionModel | None" = None
    ) -> DenoisingTerms:
        """Per-sample denoising losses of one training draw (augmentation, noise, timesteps), and, given
        a frozen ``reference`` model of the same architecture, its prediction for the same draw: the
        same noisy chunk and timestep, and the same crop and colour jitter of the observation."""
        cond, trajectory, reference_cond = self.conditioned_chunk(batch, reference)
        noise = torch.randn_like(trajectory)
        # Input perturbation (UMI): the model sees slightly more noise than it is asked to predict.
        perturbed = noise + self.config.input_perturbation * torch.randn_like(trajectory)
        if self.config.train_on_sampler_timesteps:
            visited = self.sampler_timesteps().to(trajectory.device)
            timesteps = visited[torch.randint(0, len(visited), (trajectory.shape[0],), device=visited.device)]
        else:
            timesteps = torch.randint(
                0, self.config.num_train_timesteps, (trajectory.shape[0],), device=trajectory.device
            )
        noisy = self.noise_scheduler.add_noise(trajectory, perturbed, timesteps)
        prediction = self.unet(noisy, timesteps, global_cond=cond)
        target = noise if self.config.prediction_type == "epsilon" else trajectory
        loss = F.mse_loss(prediction, target, reduction="none").mean(dim=(1, 2))
        reference_prediction = None
        if reference is not None:
            with torch.no_grad():
                reference_prediction = reference.unet(noisy, timesteps, global_cond=reference_cond)
        return DenoisingTerms(loss=loss, prediction=prediction, reference_prediction=reference_prediction)

    def sampler_timesteps(self) -> Tensor:
        """The timesteps DDIM visits with ``num_inference_steps`` (its spacing), first to last; the
        scheduler is left set to them, as ``sample`` steps with it."""
        self.noise_scheduler.set_timesteps(self.config.num_inference_steps)
        return self.noise_scheduler.timesteps.clone()

    def reset_sampler(self) -> Tensor:
        """Set the sampling scheduler to DDIM's timesteps (``sampler_timesteps``), which clears
        DPM-Solver++'s per-chunk history, and return them; ``denoise`` steps from here."""
        visited = self.sampler_timesteps()
        if self.sampling_scheduler is not self.noise_scheduler:
            self.sampling_scheduler.set_timesteps(timesteps=visited.tolist())
        return visited

    def _onnx_session(
        self, key: tuple, module: Callable[[], nn.Module], inputs: dict[str, Tensor]
    ) -> OnnxModule:
        """The ONNX Runtime session for ``key``: exported from ``module()`` when new or stale (a factory,
        so a wrapper module is only built for an export)."""
        session = self._onnx_sessions.get(key)
        if session is None or session.stale:  # new, or the weights changed since its export
            session = self._onnx_sessions[key] = OnnxModule(module(), inputs)
        return session

    def _loop_key(self, batch_size: int) -> tuple:
        """The ONNX loop session's key: its scheduler steps are constants of the graph, so the sampler and
        the step count are part of it (the spacing is fixed at construction)."""
        name = type(self.sampling_scheduler).__name__
        return ("loop", batch_size, name, self.config.num_inference_steps)

    def has_current_onnx_sessions(self, batch_size: int) -> bool:
        """Whether a chunk of ``batch_size`` on the ONNX path would export nothing: the encoder's and the
        loop's sessions for it exist and no weight changed since their export."""
        encoders = [s for k, s in self._onnx_sessions.items() if k[0] == "encoder" and k[1][0] == batch_size]
        loop = self._onnx_sessions.get(self._loop_key(batch_size))
        return bool(encoders) and loop is not None and not any(s.stale for s in [*encoders, loop])

    def _denoiser(self, sample: Tensor, timestep: Tensor, cond: Tensor) -> Callable[..., Tensor]:
        """The UNet to call during sampling: in eval mode its ONNX Runtime session (``onnx_inference``,
        on a CPU) or its TorchScript trace (``jit_inference``), else the module itself. The trace holds the
        same parameter tensors, so in-place updates (EMA, loading a state dict) need no re-trace; the
        session is re-exported after them; autocast and training keep the eager module."""
        if self.training or torch.is_autocast_enabled(cond.device.type):
            return self.unet
        if self.config.onnx_inference and cond.device.type == "cpu":
            inputs = {"sample": sample, "timestep": timestep, "global_cond": cond}
            return self._onnx_session(("unet", cond.shape[0]), lambda: self.unet, inputs)
        if not self.config.jit_inference:
            return self.unet
        key = (cond.device, cond.dtype, cond.shape[0])
        if key not in self._traced_unets:
            with torch.no_grad(), warnings.catch_warnings():
                # torch >= 2.9 marks trace deprecated (in favour of torch.compile, whose first call
                # compiles for tens of seconds in every eval worker); group_norm's batch-size check
                # becomes a constant, which is why the key holds the batch size.
                warnings.simplefilter("ignore")
                self._traced_unets[key] = torch.jit.trace(
                    self.unet, (sample, timestep, cond), check_trace=False
                )
        return self._traced_unets[key]

    def denoise(
        self,
        sample: Tensor,
        cond: Tensor,
        unet: Callable[..., Tensor],
        guide: Guide | None = None,
        generator: torch.Generator | None = None,
    ) -> Tensor:
        """Noise (B, horizon, 10) -> scaled chunk: every step of the sampling scheduler, which must be
        set to its timesteps (``sample`` does). Deterministic for DDIM (eta 0) and DPM-Solver++."""
        scheduler = self.sampling_scheduler
        # DDIM clips its own x0 estimate; DPM-Solver++ has no such option, so a predicted clean
        # chunk is clipped here, the same bound on the data the model was trained on.
        clip_x0 = scheduler is not self.noise_scheduler and self.config.clip_sample
        for t in scheduler.timesteps:
            timestep = torch.full((cond.shape[0],), int(t), dtype=torch.long, device=cond.device)
            output = unet(sample, timestep, cond)
            if guide is not None:
                output = output + guide(output)
            if clip_x0 and self.config.prediction_type == "sample":
                output = output.clamp(-self.config.clip_sample_range, self.config.clip_sample_range)
            sample = scheduler.step(output, t, sample, generator=generator).prev_sample
        return sample

    @torch.no_grad()
    def sample(
        self, batch: dict[str, Tensor], generator: torch.Generator | None = None, guide: Guide | None = None
    ) -> Tensor:
        """Relative action chunk (B, horizon, 10), unscaled, relative to the latest observed pose.

        ``guide`` (e.g. ``rl.q_guidance``) maps each denoising step's predicted clean chunk (scaled) to a
        correction added to it before the scheduler step; it needs ``prediction_type="sample"``.
        """
        if guide is not None and self.config.prediction_type != "sample":
            raise ValueError(
                f"guided sampling needs prediction_type='sample' (this policy predicts "
                f"{self.config.prediction_type!r})"
            )
        cond = self.global_condition(*self._inputs(batch))  # once per chunk, not per denoising step
        sample = torch.randn(
            (cond.shape[0], self.config.horizon, 10),
            generator=generator,
            device=cond.device,
            dtype=cond.dtype,
        )
        # As _denoiser: training and autocast keep PyTorch.
        eval_on_cpu = not self.training and cond.device.type == "cpu" and not torch.is_autocast_enabled("cpu")
        if self.config.onnx_inference and guide is None and eval_on_cpu:
            # The whole loop as one graph (a guide is Python: it needs the loop below). Its scheduler steps
            # are constants of the graph, so the Python scheduler is set only for an export (DenoisingLoop);
            # the step count is the rest of the timesteps' key (the spacing is fixed at construction).
            inputs = {"sample": sample, "global_cond": cond}
            loop = self._onnx_session(self._loop_key(cond.shape[0]), lambda: DenoisingLoop(self), inputs)
            return self.action_scaler.inverse(loop(sample, cond))
        self.reset_sampler()
        timestep = torch.zeros(cond.shape[0], dtype=torch.long, device=cond.device)
        unet = self._denoiser(sample, timestep, cond)  # chosen (and traced if new) once per chunk
        return self.action_scaler.inverse(self.denoise(sample, cond, unet, guide, generator))


class DenoisingLoop(nn.Module):
    """``BboxDiffusionModel.denoise`` with the model's UNet as a module of its own, for export: the
    loop's parameters are the UNet's, and its scheduler steps become constants of the traced graph."""

    def __init__(self, model: BboxDiffusionModel) -> None:
        super().__init__()
        model.reset_sampler()  # the export traces one chunk, stepping the scheduler from its first timestep
        self.unet = model.unet
        self._denoise = model.denoise  # a bound method, not a submodule: only the UNet is exported

    def forward(self, sample: Tensor, global_cond: Tensor) -> Tensor:
        """The scaled chunk the sampler reaches from ``sample``."""
        return self._denoise(sample, global_cond, self.unet)


# ``(policy, observations (B, n_obs, ...), generator) -> absolute chunk (B, horizon, 10)``: how
# ``select_action`` gets a new chunk; e.g. ``rl.rerank.QRerankSelector`` (sample N, keep the argmax-Q one).
ChunkSelector = Callable[["BboxDiffusionPolicy", dict[str, Tensor], torch.Generator | None], Tensor]


class BboxDiffusionPolicy(PreTrainedPolicy):
    """Bbox-conditioned diffusion policy (LeRobot plugin ``bbox_diffusion``)."""

    config_class = BboxDiffusionConfig
    name = "bbox_diffusion"

    def __init__(self, config: BboxDiffusionConfig, **kwargs) -> None:
        super().__init__(config)
        config.validate_features()
        self.config = config
        self.model = BboxDiffusionModel(config)
        # EMA copy used for inference (UMI); saved with the checkpoint beside the trained weights.
        self.ema_model = deepcopy(self.model).requires_grad_(False) if config.use_ema else None
        if self.ema_model is not None:
            # One config for the policy and both models: deepcopy gave the EMA model its own, so a setting
            # changed on a live policy (num_inference_steps, onnx_inference) missed the model that samples.
            self.ema_model.config = config
        self._ema_updates = 0
        self.chunk_selector: ChunkSelector | None = None
        # The advantage-weighted objective (rl.advantage_weighting), built on the first training batch
        # when the config asks for it; its frozen critic and reference are not modules of this policy.
        self._fine_tuning = None
        self._relabels = None  # the PA-RL relabel cache (rl.pa_rl), loaded on the first training batch
        # Seconds on one monotonic clock; latency compensation reads it (tests set a fake one).
        self.clock: Callable[[], float] = time.monotonic
        self.reset()

    def get_optim_params(self) -> list[dict]:
        """Two parameter groups: the backbone (lr scaled by encoder_lr_scale) and the rest."""
        backbone = self.model.backbone_parameters()
        backbone_ids = {id(p) for p in backbone}
        rest = [p for p in self.model.parameters() if id(p) not in backbone_ids]
        return [
            {"params": backbone, "lr": self.config.optimizer_lr * self.config.encoder_lr_scale},
            {"params": rest},
        ]

    @torch.no_grad()
    def update(self) -> None:
        """EMA step after each optimiser step: decay = 1 - (1 + step)^-power, capped at ema_max_decay."""
        if self.ema_model is None:
            return
        self._ema_updates += 1
        decay = min(
            self.config.ema_max_decay, max(0.0, 1 - (1 + self._ema_updates) ** -self.config.ema_power)
        )
        # One foreach kernel over all tensors rather than two ops per tensor (the per-tensor dispatch is
        # most of the cost for this small model on a CPU): ema + (1 - decay) * (p - ema).
        ema_params = list(self.ema_model.parameters())
        params = [p.detach() for p in self.model.parameters()]
        if len(ema_params) != len(params):
            raise RuntimeError("the EMA model and the model have different parameters")
        torch._foreach_lerp_(ema_params, params, 1 - decay)
        for ema_b, b in zip(self.ema_model.buffers(), self.model.buffers(), strict=True):
            ema_b.copy_(b)

    def _inference_model(self) -> BboxDiffusionModel:
        return self.ema_model if self.ema_model is not None else self.model

    def reset(self) -> None:
        """Clear the observation history and the action queue (call at every episode start). In eval mode
        with ``onnx_inference`` it also warms up (``warm_up``): LeRobot's rollout and eval loops reset
        before an episode, so the graphs' export (seconds) happens there, not at the episode's first step."""
        keys = [OBS_STATE, self.config.image_key]
        if self.config.bbox_mode != "none":
            keys.append(self.config.bbox_feature_key)
        self._queues = {k: deque(maxlen=self.config.n_obs_steps) for k in keys}
        self._actions: deque[Tensor] = deque()
        # Not in train mode: __init__ resets before from_pretrained loads the weights (and sets eval).
        if self.config.onnx_inference and not self.training:
            self.warm_up()

    @torch.no_grad()
    def warm_up(self, batch_size: int = 1) -> None:
        """Sample one chunk from a placeholder observation of the configured shapes, so that what the first
        real chunk would build (ONNX Runtime sessions, TorchScript traces) exists; nothing is built again
        while it is current. The observation queues and the action queue are left untouched."""
        model = self._inference_model().eval()
        if self.config.onnx_inference and model.has_current_onnx_sessions(batch_size):
            return  # an episode's reset after the first: the next chunk reuses them
        device = torch.device(self.config.device or "cpu")
        t = self.config.n_obs_steps
        image_shape = self.config.input_features[self.config.image_key].shape
        batch = {self.config.image_key: torch.full((batch_size, t, *image_shape), 0.5)}
        identity = np.append(mat_to_pose9(np.eye(4)), 0.0)  # a valid pose10: identity pose, gripper 0
        batch[OBS_STATE] = torch.as_tensor(identity, dtype=torch.float32).expand(batch_size, t, 10)
        if self.config.bbox_mode != "none":
            batch[self.config.bbox_feature_key] = torch.tensor([0.25, 0.25, 0.75, 0.75]).expand(
                batch_size, t, 4
            )
        own_noise = torch.Generator(device).manual_seed(0)  # leaves torch's global random state alone
        model.sample({k: v.to(device) for k, v in batch.items()}, generator=own_noise)

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        """Training loss: the denoising loss, the step-distillation loss when the config names a teacher
        (``distill_teacher_path``), or the advantage-weighted objective when it names a
        critic, measured advantages or a reference policy (``awr_critic_path`` / ``awr_advantages_path`` /
        ``anchor_policy_path``), on the batch's action
        chunks or, where a PA-RL cache (``parl_cache_path``) holds a valid entry, on its optimised ones."""
        if self._relabels is None and self.config.parl_cache_path:
            from lerobot_bboxpick.rl.pa_rl import RelabelCache  # rl imports us

            self._relabels = RelabelCache.load(self.config.parl_cache_path)
        if self._relabels is not None:
            batch = self._relabels.apply(batch)
        if self._fine_tuning is None and self.config.advantage_weighted:
            from lerobot_bboxpick.rl.advantage_weighting import AdvantageWeightedLoss  # rl imports us

            self._fine_tuning = AdvantageWeightedLoss.from_config(self.config)
        if self._fine_tuning is None and self.config.distill_teacher_path:
            from lerobot_bboxpick.policies.bbox_diffusion.step_distillation import StepDistillationLoss

            self._fine_tuning = StepDistillationLoss.from_config(self.config)
        if self._fine_tuning is not None:
            return self._fine_tuning(self.model, batch)
        loss = self.model.compute_loss(batch)
        return loss, {"diffusion_loss": loss.item()}

    @torch.no_grad()
    def predict_action_chunk(
        self, batch: dict[str, Tensor], generator: torch.Generator | None = None, guide: Guide | None = None
    ) -> Tensor:
        """Absolute action chunk (B, horizon, 10) for a batch with (B, n_obs, ...) observations (a batch
        of single observations without a time axis is taken as one observed step).

        Sampling leaves an enclosing autocast (``lerobot-eval`` opens one for checkpoints trained with
        ``use_amp``) unless ``autocast_inference`` is set: see the config field.
        """
        model = self._inference_model()
        model.eval()
        device_type = next(iter(batch.values())).device.type
        with torch.autocast(
            device_type, enabled=self.config.autocast_inference and torch.is_autocast_enabled(device_type)
        ):
            relative = model.sample(batch, generator=generator, guide=guide)
        current = batch[OBS_STATE] if batch[OBS_STATE].ndim == 2 else batch[OBS_STATE][:, -1]
        with torch.autocast(device_type, enabled=False):  # pose algebra in float32, whatever encloses us
            return absolute_pose10_torch(relative.float(), current.float())

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], generator: torch.Generator | None = None) -> Tensor:
        """Next absolute action (B, 10); a new chunk is predicted every ``n_action_steps`` calls (by
        ``chunk_selector`` when one is set, else ``predict_action_chunk``)."""
        received = self.clock()
        batch = {k: v for k, v in batch.items() if k in self._queues}
        self._queues = populate_queues(self._queues, batch)
        if not self._actions:
            stacked = {k: torch.stack(list(q), dim=1) for k, q in self._queues.items()}
            if self.chunk_selector is None:
                chunk = self.predict_action_chunk(stacked, generator=generator)
            else:  # e.g. critic reranking of several sampled chunks (set by the caller, never saved)
                chunk = self.chunk_selector(self, stacked, generator)
            if self.config.compensate_latency:
                chunk = chunk[:, self._fresh_steps(chunk.shape[1], received)]
            self._actions.extend(chunk[:, : self.config.n_action_steps].transpose(0, 1))
        return self._actions.popleft()

    def _fresh_steps(self, horizon: int, received: float) -> Tensor:
        """Indices of the chunk's steps still ahead of the arm (``compensate_latency``)."""
        c = self.config
        dt = 1.0 / c.control_fps
        captured = observation_time(received, c.camera_latency_s)
        steps = fresh_steps(horizon, captured + dt, dt, self.clock(), c.action_latency_s)
        log.debug("latency compensation: %d of %d chunk steps already due, dropped", steps[0], horizon)
        return torch.as_tensor(steps, dtype=torch.long)


class BboxDiffusionPaperPolicy(BboxDiffusionPolicy):
    """The same policy with the paper's defaults (``--policy.type=bbox_diffusion_paper``)."""

    config_class = BboxDiffusionPaperConfig
    name = "bbox_diffusion_paper"
