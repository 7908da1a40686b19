"""CPU timing of candidate backbones for the bbox_diffusion ``cpu`` preset (not collected by pytest).

Run: ``.venv/bin/python tests/bench_encoders_script.py [--threads 2] [--quick]``. Prints, per backbone and
input size, MaskedImageEncoder (RGB+mask) forward+backward ms for a batch of 32 images and the implied
samples/s with 2 observation frames per sample, the forward ms for one inference call (2 frames), then
the PairedAugment cost and LeRobot's UNet cost (training step, and 16 DDIM steps at inference).
"""

import argparse
import time
from types import SimpleNamespace

import torch

from lerobot_bboxpick.policies.bbox_diffusion.encoder import MaskedImageEncoder, PairedAugment

CANDIDATES = [
    ("resnet18", 96),
    ("resnet18", 112),
    ("resnet10t", 96),
    ("resnet10t", 112),
    ("mobilenetv3_small_100", 96),
    ("efficientnet_b0", 96),
    ("regnetx_002", 96),
    ("vit_tiny_patch16_224", 96),
    ("vit_tiny_patch16_224", 112),
]


def timed(fn, reps: int) -> float:
    """Median wall time of ``fn()`` in ms after one warm-up call."""
    fn()
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1000 * sorted(times)[len(times) // 2]


def bench_encoder(name: str, size: int, batch: int, reps: int) -> dict:
    """Train step (fwd+bwd) on ``batch`` images and an inference forward on 2 images."""
    torch.manual_seed(0)
    enc = MaskedImageEncoder(name, pretrained=False, image_size=size, use_mask=True)
    rgb, mask = torch.rand(batch, 3, size, size), torch.rand(batch, 1, size, size)

    def train() -> None:
        enc.zero_grad(set_to_none=True)
        enc(rgb, mask).square().mean().backward()

    enc.train()
    train_ms = timed(train, reps)
    enc.eval()
    with torch.no_grad():
        infer_ms = timed(lambda: enc(rgb[:2], mask[:2]), reps * 3)
    params = sum(p.numel() for p in enc.parameters()) / 1e6
    return {"train_ms": train_ms, "infer_ms": infer_ms, "dim": enc.out_dim, "params": params}


def bench_unet(down_dims: tuple[int, ...], cond_dim: int, batch: int, reps: int) -> tuple[float, float]:
    """LeRobot's DiffusionConditionalUnet1d: train fwd+bwd on ``batch`` chunks, 16 steps at batch 1."""
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionConditionalUnet1d

    cfg = SimpleNamespace(
        action_feature=SimpleNamespace(shape=(10,)),
        down_dims=down_dims,
        kernel_size=5,
        n_groups=8,
        diffusion_step_embed_dim=128,
        use_film_scale_modulation=True,
        gradient_checkpointing=False,
    )
    unet = DiffusionConditionalUnet1d(cfg, global_cond_dim=cond_dim)
    x, cond, t = torch.randn(batch, 16, 10), torch.randn(batch, cond_dim), torch.randint(0, 50, (batch,))

    def train() -> None:
        unet.zero_grad(set_to_none=True)
        unet(x, t, global_cond=cond).square().mean().backward()

    def infer() -> None:
        y = x[:1]
        for step in range(16):
            y = unet(y, torch.tensor([step]), global_cond=cond[:1])

    train_ms = timed(train, reps)
    with torch.no_grad():
        infer_ms = timed(infer, reps)
    return train_ms, infer_ms


def main() -> None:
    """Print the tables."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="only the first and the ViT candidates")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    b = args.batch
    a = torch.rand(1024, 1024)
    gflops = 2 * 1024**3 / timed(lambda: a @ a, 10) / 1e6
    print(f"threads={torch.get_num_threads()} batch={b} images (= {b // 2} samples x 2 frames)")
    print(f"machine reference: 1024^2 fp32 matmul {gflops:.1f} GFLOP/s (compare runs by this)")
    print(f"{'backbone':24s} {'px':>4s} {'D':>5s} {'Mparam':>6s} {'fwd+bwd ms':>10s} {'img/s':>6s} "
          f"{'samples/s':>9s} {'infer 2 img ms':>14s}")  # fmt: skip
    cands = [c for c in CANDIDATES if not args.quick or c[0] in ("resnet18", "vit_tiny_patch16_224")]
    for name, size in cands:
        r = bench_encoder(name, size, b, args.reps)
        ips = 1000 * b / r["train_ms"]
        print(f"{name:24s} {size:4d} {r['dim']:5d} {r['params']:6.2f} {r['train_ms']:10.1f} {ips:6.0f} "
              f"{ips / 2:9.0f} {r['infer_ms']:14.1f}")  # fmt: skip

    aug = PairedAugment()
    rgb, mask = torch.rand(b // 2, 2, 3, 224, 224), torch.rand(b // 2, 2, 1, 224, 224)
    for size in (96, 112):
        ms = timed(lambda size=size: aug.train()(rgb, mask, size), args.reps)
        ms_eval = timed(lambda size=size: aug.eval()(rgb[:1], mask[:1], size), args.reps)
        print(
            f"PairedAugment 224->{size}: train {ms:.1f} ms per {b} images, eval {ms_eval:.1f} ms per 2 images"
        )
    for dims in ((64, 128, 256), (128, 256, 512), (256, 512, 1024)):
        train_ms, infer_ms = bench_unet(dims, 2 * (512 + 10), b // 2, args.reps)
        print(f"UNet down_dims={dims}: train fwd+bwd {train_ms:.1f} ms per {b // 2} samples, "
              f"16 DDIM steps {infer_ms:.1f} ms")  # fmt: skip


if __name__ == "__main__":
    main()
