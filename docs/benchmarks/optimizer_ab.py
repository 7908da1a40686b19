"""One batch-8 training step of the fast encoder (64 px, one frame; float32, random tensors): torch's
default AdamW and a per-tensor EMA (the policy before commit 1de123a) against the preset's fused AdamW
and foreach EMA, interleaved step by step in one process so a noisy host moves both alike.

Run from the repository root: ``.venv/bin/python docs/benchmarks/optimizer_ab.py`` (output:
``docs/benchmarks/optimizer_ab.md``).
"""

import time

import numpy as np
import torch

from lerobot_bboxpick.apps.bench import _lever_policy

BATCH = 8
STEPS = 24  # the first 4 of each arm warm up


def per_tensor_ema(policy) -> None:
    """The EMA update before the change: two ops per parameter tensor."""
    policy._ema_updates += 1
    decay = min(policy.config.ema_max_decay, 1 - (1 + policy._ema_updates) ** -policy.config.ema_power)
    with torch.no_grad():
        for ema_p, p in zip(policy.ema_model.parameters(), policy.model.parameters(), strict=True):
            ema_p.mul_(decay).add_(p.detach(), alpha=1 - decay)


def main() -> None:
    batch = {
        "observation.images.wrist": torch.rand(BATCH, 1, 3, 224, 224),
        "observation.state": torch.rand(BATCH, 1, 10),
        "observation.bbox": torch.tensor([0.4, 0.4, 0.5, 0.5]).expand(BATCH, 1, 4),
        "action": torch.rand(BATCH, 16, 10),
    }
    arms = {}
    for name in ("default AdamW, per-tensor EMA (before)", "fused AdamW, foreach EMA (after)"):
        policy = _lever_policy({"image_size": 64, "n_obs_steps": 1}).train()
        preset = policy.config.get_optimizer_preset()
        if name.endswith("(after)"):
            optimizer, update = preset.build(policy.get_optim_params()), policy.update
        else:
            kwargs = {
                "lr": preset.lr,
                "betas": preset.betas,
                "eps": preset.eps,
                "weight_decay": preset.weight_decay,
            }
            optimizer = torch.optim.AdamW(policy.get_optim_params(), **kwargs)
            update = lambda p=policy: per_tensor_ema(p)  # noqa: E731
        arms[name] = (policy, optimizer, update)
    times: dict[str, list[float]] = {name: [] for name in arms}
    for _ in range(STEPS):
        for name, (policy, optimizer, update) in arms.items():
            t0 = time.perf_counter()
            loss, _ = policy.forward(batch)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), preset.grad_clip_norm)
            optimizer.step()
            optimizer.zero_grad()
            update()
            times[name].append(time.perf_counter() - t0)
    medians = {name: float(np.median(t[4:])) for name, t in times.items()}
    before, after = medians.values()
    lines = [
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, batch {BATCH}, "
        f"median of {STEPS - 4} interleaved steps each\n",
        "| training step | s per step |",
        "|---|---|",
        *[f"| {name} | {m:.3f} |" for name, m in medians.items()],
        f"\nratio: **{before / after:.2f}x**",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    with open("docs/benchmarks/optimizer_ab.md", "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
