"""Configuration of the ``bbox_diffusion`` policies (``lerobot-train --policy.type=bbox_diffusion``).

A UMI-style diffusion policy (FACTS.md section 2) whose target bounding box enters as a mask
channel beside the wrist image (paper section 4.1). Two registered types, each with its real defaults
in the dataclass (and so in ``--help``):

* ``bbox_diffusion``: the CPU design, a from-scratch ResNet-18 (stage 2, 32 spatial-softmax keypoints)
  at 96 px, a small UNet, x0 prediction; trains on a 2-core CPU (docs/results.md).
* ``bbox_diffusion_paper``: the paper's design, CLIP ViT-L/14 at 224 px with pretrained weights, CLS
  feature, UMI's UNet (256, 512, 1024), epsilon prediction.
"""

from dataclasses import dataclass, field

from lerobot.configs import FeatureType, NormalizationMode, PolicyFeature, PreTrainedConfig
from lerobot.optim import AdamWConfig, DiffuserSchedulerConfig, OptimizerConfig

from lerobot_bboxpick.keys import BBOX, STATE

BBOX_MODES = ("mask", "lowdim", "none")
TIMESTEP_SPACINGS = ("leading", "trailing", "linspace")  # diffusers DDIMScheduler's options
SAMPLERS = ("ddim", "dpmsolver++")  # diffusers' DDIMScheduler and DPMSolverMultistepScheduler
MASK_SIZE_SCALES = ("sqrt", "log", "log_wh")  # how the mask centroid's size is scaled (encoder.mask_moments)
# The options that decide what a model's input and output are: a reference model (an anchor, a teacher)
# must share them with the model it stands beside for its predictions to be comparable.
INPUT_OUTPUT_FIELDS = (
    "horizon",
    "n_obs_steps",
    "image_size",
    "bbox_mode",
    "mask_centroid",
    "mask_size_scale",
    "crop_ratio",
)
POSE_DIM = 10  # TCP pose10: position, rot6d, gripper width
PACKED_STATE_DIM = POSE_DIM + 4  # the ur5 robot's observation.state: pose10 then the bbox


@OptimizerConfig.register_subclass("adamw_fused")
@dataclass
class FusedAdamWConfig(AdamWConfig):
    """LeRobot's AdamW with torch's fused kernel (``--optimizer.type=adamw_fused``).

    On a CPU, torch.optim.AdamW defaults to a Python loop over the parameter tensors: for this policy's
    180 tensors that is 63 ms of a ~0.3 s batch-8 step on a 2-core AVX2 CPU; the fused kernel takes
    13 ms for the same update (docs/benchmarks.md). The parent's ``build`` passes ``fused`` on.
    """

    fused: bool = True


@PreTrainedConfig.register_subclass("bbox_diffusion")
@dataclass
class BboxDiffusionConfig(PreTrainedConfig):
    """Options of the bbox-conditioned diffusion policy."""

    # Observation and action horizons (UMI): 2 observed steps, a 16-step chunk starting at the current
    # step, of which n_action_steps are executed before predicting again (12 of 16 re-checked on
    # validation seeds for the CPU recipe, docs/results.md; the paper type executes 8).
    n_obs_steps: int = 2
    horizon: int = 16
    n_action_steps: int = 12

    # How the target bbox enters: "mask" (4th image channel, the paper's method), "lowdim" (the four
    # numbers join the low-dimensional conditioning, paper Exp. 6), "none" (no target prompt, Exp. 1).
    bbox_mode: str = "mask"
    # With bbox_mode="mask": also append the *augmented* mask's centroid, size and visibility (4 numbers
    # per frame) to the low-dim conditioning. Unlike the raw bbox (paper Exp. 6) they are measured after
    # the random crop, so they stay consistent with the pixels; they hand a from-scratch encoder the
    # target's image position directly instead of making it find the mask through the CNN.
    # Only used with bbox_mode="mask": the ablation modes have no mask, so it is turned off for them.
    mask_centroid: bool = True
    # The scale of that size (MASK_SIZE_SCALES): "sqrt" (2 * sqrt(area fraction) - 1, what every
    # checkpoint before 2026-12-07 used) or "log" (ln sqrt(area fraction) + 3, clamped to +-3). A small
    # target's size is the one place its distance is measured to the millimetre (a stacked pile brick
    # at the close is 8% larger than one on the table, less than a pixel at 64 px); "sqrt" squeezes
    # that into 0.01, "log" keeps it at 0.08. Measured (docs/results.md): with "log" the height recipe
    # closes at the right height on aligned stacked bricks and never closes on turned ones (a turned
    # brick's box is larger at the same distance): 39% of the validation scenes against 88%.
    # "log_wh" gives the box's width and height apart on that log scale (5 centroid numbers, not 4): a
    # nearer brick's box grows on both sides, a turned one's mostly on one. Measured: 34%; both log
    # scales lose the grid settings too (a size that moves over each demo becomes the close's clock).
    mask_size_scale: str = "sqrt"
    # Also condition on the gripper's height above the table: the observed TCP z (observation.state[2])
    # minus ``table_height`` (the table top's z in the state's frame: the robot base on a UR5, the world
    # in lego_pick, whose table top is at 0), divided by ``height_input_scale``, per observed frame.
    # UMI's poses are all relative to the current one, so a one-frame policy's height above the brick
    # can only come from the picture, where a turned brick looks nearer than an aligned one
    # (docs/results.md, "turned targets"). Off by default: it needs a state frame fixed to the table,
    # which lerobot_bboxpick's sim and a mounted UR5 have and hand-held UMI data has not.
    height_input: bool = False
    table_height: float = 0.0
    height_input_scale: float = 0.15
    # timm backbone by name; pretrained weights are loaded by timm (fails clearly when they cannot be).
    backbone: str = "resnet18"
    pretrained_backbone: bool = False
    image_size: int = 96
    # "default": timm's pooled feature (CLS token for ViTs, as UMI); "spatial_softmax": a CNN cut after
    # timm stage ``feature_stage`` whose map becomes ``num_keypoints`` (x, y) keypoints.
    pooling: str = "spatial_softmax"
    feature_stage: int = 2
    num_keypoints: int = 32
    # GroupNorm instead of BatchNorm in CNN backbones trained from scratch.
    group_norm: bool = True
    crop_ratio: float = 0.95
    # ColorJitter (brightness, contrast, saturation, hue), UMI's values.
    color_jitter: tuple[float, float, float, float] = (0.3, 0.4, 0.5, 0.08)
    # The target view (``target_crop``): with target_crop_size > 0, a square window around the target's
    # box, target_crop_context times its longer side (at least target_crop_min_side of the image), is
    # resampled to target_crop_size px from the stored frame and encoded by a second encoder of the same
    # architecture, its feature joining the global condition. 0: off (the shipped recipe's input).
    target_crop_size: int = 0
    target_crop_context: float = 3.0
    target_crop_min_side: float = 0.1

    # UNet (LeRobot's DiffusionConditionalUnet1d).
    down_dims: tuple[int, ...] = (64, 128, 256)
    kernel_size: int = 5
    n_groups: int = 8
    diffusion_step_embed_dim: int = 64
    use_film_scale_modulation: bool = True
    gradient_checkpointing: bool = False
    # Run the UNet's 16 denoising calls per chunk through a TorchScript trace at inference (eval mode,
    # no autocast). Same numbers (< 1e-5) in ~60% of the time on CPU, where this small UNet is bound by
    # Python dispatch; the trace shares the weights, so EMA updates and loaded checkpoints are seen.
    jit_inference: bool = True
    # Run the image encoder and each chunk's whole denoising loop as ONNX Runtime graphs instead (the
    # ``onnx`` extra; CPU only; eval mode, no autocast): the same chunks (< 1e-4) without PyTorch's per-op
    # dispatch or Python between the steps (docs/benchmarks.md, "ONNX Runtime").
    onnx_inference: bool = False
    # ``use_amp`` is a training flag here, but lerobot-eval also samples under autocast when it is set.
    # On a CPU bf16 sampling is eager and slower than the float32 trace (docs/benchmarks.md), so
    # sampling runs in float32 unless this is set (e.g. on a GPU where bf16 inference pays).
    autocast_inference: bool = False

    # Latency compensation on a real arm (UMI; lerobot_bboxpick.latency). With compensate_latency, a new
    # chunk's observation counts as captured camera_latency_s before select_action received it; its step
    # i is due (i + 1) / control_fps after that (our datasets record at frame t the target reached at
    # t + 1) and must be commanded action_latency_s earlier; the steps whose command time passed while
    # the frame travelled and the chunk was sampled are dropped, the rest executed one per tick. Off in
    # simulation, which has no latency (and lerobot-eval does not run in real time). Defaults: GoPro
    # through an Elgato capture card (0.17 s), a UR5e servoing with lookahead 0.1 s; 20 Hz control.
    compensate_latency: bool = False
    camera_latency_s: float = 0.17
    action_latency_s: float = 0.1
    control_fps: float = 20.0

    # Noise schedule (UMI: DDIM, 50 train steps, squaredcos_cap_v2, epsilon, clip_sample).
    num_train_timesteps: int = 50
    num_inference_steps: int = 16
    # Which num_inference_steps of the num_train_timesteps DDIM visits (diffusers' DDIMScheduler option).
    # "leading" (the default, what every published table used) starts at (T // n) * (n - 1): at 4 of 50
    # steps, t = 36, where the model expects 39% signal in what is pure noise; "trailing" and "linspace"
    # start at t = T - 1 whatever n (Lin et al. 2023, "Common Diffusion Noise Schedules and Sample Steps
    # are Flawed", table 2). For the shipped checkpoint both picked fewer, not more (docs/results.md).
    timestep_spacing: str = "leading"
    # Which solver integrates the sampling ODE, at the timesteps DDIM would visit (so its last model call
    # is at t = 0 too); training is the same for both. "ddim" is first order (every published table);
    # "dpmsolver++" (Lu et al. 2022, 2M) is a second-order multistep solver reusing the previous call's
    # prediction: one UNet call per step as DDIM. For the shipped checkpoint it lands further from the
    # converged chunk than DDIM on average at 4-8 calls (docs/benchmarks.md), so "ddim" stays the default.
    sampler: str = "ddim"
    # Train only at the timesteps DDIM visits with num_inference_steps (a model for few-step sampling):
    # the denoiser's capacity goes to the few noise levels it is asked about at inference, instead of all
    # num_train_timesteps. Off: uniform over all of them (every published checkpoint).
    train_on_sampler_timesteps: bool = False
    beta_schedule: str = "squaredcos_cap_v2"
    beta_start: float = 0.0001
    beta_end: float = 0.02
    prediction_type: str = "sample"
    clip_sample: bool = True
    clip_sample_range: float = 1.0
    input_perturbation: float = 0.1

    # Fixed scales of the relative-pose representation (see modeling_bbox_diffusion.PoseScaler): positions of
    # the action chunk relative to the current pose are divided by action_position_scale, positions of
    # the previous observation by obs_position_scale; gripper widths map [0, max_gripper_width] to [-1, 1].
    # 0.15 m: the expert's 16-step chunks move at most 0.146 m from the current pose (99th pct 0.12 m).
    action_position_scale: float = 0.15
    # The chunk's rotation (rot6d, relative to the current pose) enters as identity + (R - identity) /
    # action_rotation_scale. 1.0 (every published checkpoint): unscaled, as UMI. The expert's turns are
    # small: the yaw entries of its relative chunks span +-0.36 (99.9th pct; std 0.05 against the
    # positions' 0.17-0.28 after scaling), so at 1.0 a turn is below the noise of the last denoising steps;
    # 0.36 maps that range onto [-1, 1], the min-max normalisation LeRobot's diffusion policy gives
    # every action dimension.
    action_rotation_scale: float = 1.0
    obs_position_scale: float = 0.02
    max_gripper_width: float = 0.09

    # Optimiser (UMI): AdamW 3e-4, betas (0.95, 0.999), weight decay 1e-6; encoder lr scaled when pretrained.
    optimizer_lr: float = 3e-4
    optimizer_betas: tuple[float, float] = (0.95, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 1e-6
    optimizer_grad_clip_norm: float = 10.0
    encoder_lr_scale: float = 1.0
    scheduler_name: str = "cosine"
    scheduler_warmup_steps: int = 200
    # EMA of the weights (UMI: power 0.75, max decay 0.9999), updated by ``update()`` after each step.
    use_ema: bool = True
    ema_power: float = 0.75
    ema_max_decay: float = 0.9999

    # Advantage-weighted fine-tuning (paper section 6.2; ``lerobot_bboxpick.rl.advantage_weighting``), off
    # unless a critic or a reference is given. Each chunk's denoising loss is weighted by
    # min(exp(A / awr_temperature), awr_max_weight), A = Q(s, a) - V(s) of the frozen critic at
    # ``awr_critic_path`` (a ``bboxpick-train-critic`` / ``bboxpick-train-mc-critic`` checkpoint warm-started
    # from this policy); ``awr_bc_weight`` adds the unweighted loss, and ``anchor_weight`` an MSE between
    # this model's denoised prediction and the frozen reference policy's at ``anchor_policy_path`` (same
    # noisy chunk, timestep and augmented observation): the paper's stabilisers. Training only.
    # ``awr_advantages_path`` instead of a critic: measured advantages per training episode (a
    # ``bboxpick-branch-advantages`` file: counterfactual successes' G - V from the simulator).
    awr_critic_path: str | None = None
    awr_advantages_path: str | None = None
    awr_temperature: float = 1.0
    awr_max_weight: float = 20.0
    awr_bc_weight: float = 1.0
    anchor_policy_path: str | None = None
    anchor_weight: float = 0.5
    # PA-RL (paper section 6.3; ``lerobot_bboxpick.rl.pa_rl``): a ``bboxpick-parl-relabel`` cache of
    # critic-optimised chunks by dataset frame index; where its entry is valid, the loss imitates that
    # chunk instead of the dataset's (with ``anchor_policy_path``: the paper's anchor). Training only.
    parl_cache_path: str | None = None
    # Progressive step distillation (``step_distillation``): a frozen teacher checkpoint of this
    # architecture; each of this policy's num_inference_steps DDIM steps learns to land where two of the
    # teacher's steps land when it steps 2 x num_inference_steps times (whatever its own
    # num_inference_steps): half the UNet calls per chunk. Training only.
    distill_teacher_path: str | None = None

    # Checkpoints stay local unless asked: this machine (and many labs) has no Hub access.
    push_to_hub: bool = False
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            # Poses are made relative and scaled by the policy's own steps; images are normalised by
            # the backbone's mean/std; the bbox is already in [0, 1].
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.IDENTITY,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.bbox_mode not in BBOX_MODES:
            raise ValueError(f"bbox_mode={self.bbox_mode!r} is not one of {', '.join(BBOX_MODES)}")
        if self.bbox_mode != "mask":
            self.mask_centroid = False  # no mask to measure (see the field)
        if self.mask_size_scale not in MASK_SIZE_SCALES:
            raise ValueError(
                f"mask_size_scale={self.mask_size_scale!r} is not one of {', '.join(MASK_SIZE_SCALES)}"
            )
        if not 0.0 < self.action_rotation_scale <= 1.0:
            raise ValueError(f"action_rotation_scale={self.action_rotation_scale!r} must be in (0, 1]")
        if not self.height_input_scale > 0.0:
            raise ValueError(f"height_input_scale={self.height_input_scale!r} must be > 0 (metres)")
        if self.pooling not in ("default", "spatial_softmax"):
            raise ValueError(f"pooling={self.pooling!r} must be 'default' or 'spatial_softmax'")
        self.down_dims = tuple(self.down_dims)
        if not 1 <= self.n_action_steps <= self.horizon:
            raise ValueError(f"n_action_steps={self.n_action_steps} must be in [1, horizon={self.horizon}]")
        if self.prediction_type not in ("epsilon", "sample"):
            raise ValueError(f"prediction_type={self.prediction_type!r} must be 'epsilon' or 'sample'")
        if self.timestep_spacing not in TIMESTEP_SPACINGS:
            raise ValueError(
                f"timestep_spacing={self.timestep_spacing!r} is not one of {', '.join(TIMESTEP_SPACINGS)}"
            )
        if self.sampler not in SAMPLERS:
            raise ValueError(f"sampler={self.sampler!r} is not one of {', '.join(SAMPLERS)}")
        for name in ("camera_latency_s", "action_latency_s"):
            if not 0.0 <= getattr(self, name) < 10.0:
                raise ValueError(f"{name}={getattr(self, name)!r} must be in [0, 10) seconds")
        if not 0.0 < self.control_fps <= 1000.0:
            raise ValueError(f"control_fps={self.control_fps!r} must be in (0, 1000] Hz")
        if self.target_crop_size != 0 and not 16 <= self.target_crop_size <= 512:
            raise ValueError(f"target_crop_size={self.target_crop_size} must be 0 (off) or in [16, 512] px")
        if self.target_crop_size and self.bbox_mode == "none":
            raise ValueError(
                "target_crop_size > 0 needs the target's box: bbox_mode must be 'mask' or 'lowdim'"
            )
        if not self.target_crop_context >= 1.0:
            raise ValueError(f"target_crop_context={self.target_crop_context!r} must be >= 1 (box sides)")
        if not 0.0 < self.target_crop_min_side <= 1.0:
            raise ValueError(f"target_crop_min_side={self.target_crop_min_side!r} must be in (0, 1]")
        if not 0.5 <= self.crop_ratio <= 1.0:
            raise ValueError(f"crop_ratio={self.crop_ratio} must be in [0.5, 1]")
        if not self.awr_temperature > 0.0:
            raise ValueError(f"awr_temperature={self.awr_temperature!r} must be > 0")
        if not self.awr_max_weight >= 1.0:
            raise ValueError(f"awr_max_weight={self.awr_max_weight!r} must be >= 1")
        if self.awr_critic_path is not None and self.awr_advantages_path is not None:
            raise ValueError(
                "awr_critic_path and awr_advantages_path are both set: weight by a critic or by measured "
                "advantages, not both"
            )
        if self.distill_teacher_path is not None and (self.advantage_weighted or self.parl_cache_path):
            raise ValueError(
                "distill_teacher_path is set with awr_critic_path / awr_advantages_path / "
                "anchor_policy_path / parl_cache_path: step distillation is its own objective, set one"
            )
        if self.distill_teacher_path is not None and self.sampler != "ddim":
            raise ValueError(
                f"distill_teacher_path needs sampler='ddim' (it learns DDIM steps), not {self.sampler!r}"
            )
        for name in ("awr_bc_weight", "anchor_weight"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name}={getattr(self, name)!r} must be >= 0")

    def get_optimizer_preset(self) -> AdamWConfig:
        """AdamW with UMI's settings, fused."""
        return FusedAdamWConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            eps=self.optimizer_eps,
            weight_decay=self.optimizer_weight_decay,
            grad_clip_norm=self.optimizer_grad_clip_norm,
        )

    def get_scheduler_preset(self) -> DiffuserSchedulerConfig:
        """Cosine schedule with linear warm-up."""
        return DiffuserSchedulerConfig(name=self.scheduler_name, num_warmup_steps=self.scheduler_warmup_steps)

    def validate_features(self) -> None:
        """The policy needs the wrist image, the 10-float state, the bbox (unless bbox_mode='none')
        and a 10-float action.

        A 14-float state without a bbox feature is the ``ur5`` robot's packed layout (pose10 then the
        bbox, as ``lerobot-record`` stores it): the features are split here and the preprocessor's
        ``UnpackBboxFromStateStep`` splits the tensors, so such datasets train unchanged.
        """
        state = self.input_features.get(STATE)
        if state is not None and state.shape == (PACKED_STATE_DIM,) and BBOX not in self.input_features:
            self.input_features[STATE] = PolicyFeature(type=FeatureType.STATE, shape=(POSE_DIM,))
            bbox_shape = (PACKED_STATE_DIM - POSE_DIM,)
            self.input_features[BBOX] = PolicyFeature(type=FeatureType.STATE, shape=bbox_shape)
        if not self.image_features:
            raise ValueError("bbox_diffusion needs an image input feature (observation.images.*)")
        if self.robot_state_feature is None or self.robot_state_feature.shape != (10,):
            raise ValueError("bbox_diffusion needs observation.state of shape (10,) (TCP pose10)")
        if self.bbox_mode != "none" and self.bbox_feature_key not in self.input_features:
            raise ValueError(f"bbox_mode={self.bbox_mode!r} needs the input feature {self.bbox_feature_key}")
        if self.action_feature is None or self.action_feature.shape != (10,):
            raise ValueError("bbox_diffusion needs an action of shape (10,) (TCP pose10)")

    @property
    def advantage_weighted(self) -> bool:
        """Whether training uses the advantage-weighted objective (``rl.advantage_weighting``): a critic,
        measured advantages or a reference policy is named."""
        return bool(self.awr_critic_path or self.awr_advantages_path or self.anchor_policy_path)

    @property
    def bbox_feature_key(self) -> str:
        """Name of the bbox observation."""
        return BBOX

    @property
    def image_key(self) -> str:
        """The (single) wrist camera input."""
        return next(iter(self.image_features))

    @property
    def observation_delta_indices(self) -> list[int] | None:
        """The previous and the current step; None for the current step alone, which LeRobotDataset
        then reads from the frame's own row instead of querying a window per key (each window query
        deep-copies the dataset's features: 1.5x the loader's samples/s, docs/benchmarks.md)."""
        if self.n_obs_steps == 1:
            return None
        return list(range(1 - self.n_obs_steps, 1))

    @property
    def action_delta_indices(self) -> list[int]:
        """The chunk starts at the current step (UMI), not n_obs_steps - 1 steps in the past."""
        return list(range(self.horizon))

    @property
    def reward_delta_indices(self) -> None:
        """No rewards."""
        return None


@PreTrainedConfig.register_subclass("bbox_diffusion_paper")
@dataclass
class BboxDiffusionPaperConfig(BboxDiffusionConfig):
    """The paper's design (section 4.1, UMI's recipe): CLIP ViT-L/14 at 224 px with pretrained weights,
    its CLS token as the image feature, UMI's UNet, epsilon prediction, 8 executed steps per chunk."""

    n_action_steps: int = 8
    mask_centroid: bool = False
    backbone: str = "vit_large_patch14_clip_224.openai"
    pretrained_backbone: bool = True
    image_size: int = 224
    pooling: str = "default"
    group_norm: bool = False
    down_dims: tuple[int, ...] = (256, 512, 1024)
    diffusion_step_embed_dim: int = 128
    prediction_type: str = "epsilon"
    encoder_lr_scale: float = 0.1
    scheduler_warmup_steps: int = 2000
