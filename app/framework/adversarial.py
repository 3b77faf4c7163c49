"""Training G: Algorithm 1 (through the frozen FC_Y) and Algorithm 2 (against D)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from app.framework.generator import noisy
from app.framework.progress import bar_disabled


def _frozen(*modules: nn.Module) -> None:
    for m in modules:
        m.eval()
        for p in m.parameters():
            p.requires_grad_(False)


def train_generator_through_classifier(
    generator: nn.Module,
    fc_y: nn.Module,
    attributes: np.ndarray,
    epochs: int,
    noise_std: float = 0.1,
    batch_size: int = 50,
    lr: float = 1e-3,
    seed: int = 0,
    progress: bool = False,
) -> list[float]:
    """Algorithm 1: G learns to make features that the frozen FC_Y classifies as y_n.

    ``attributes`` row n describes known class n. Returns the mean loss per epoch.
    """
    gen = torch.Generator().manual_seed(seed)
    _frozen(fc_y)
    a = torch.as_tensor(attributes, dtype=torch.float32)
    y = torch.arange(len(a))
    opt = torch.optim.Adam(generator.parameters(), lr=lr, betas=(0.5, 0.999))
    loss_fn = nn.CrossEntropyLoss()
    generator.train()
    history = []
    for _ in tqdm(
        range(epochs), desc="G, Algorithm 1", disable=bar_disabled(progress), leave=False
    ):
        losses = []
        for idx in torch.randperm(len(a), generator=gen).split(batch_size):
            opt.zero_grad()
            loss = loss_fn(fc_y(generator(noisy(a[idx], noise_std, gen))), y[idx])
            loss.backward()
            opt.step()
            losses.append(loss.item())
        history.append(float(np.mean(losses)))
    generator.eval()
    return history


def train_adversarially(
    generator: nn.Module,
    discriminator: nn.Module,
    fc_y: nn.Module,
    attributes: np.ndarray,
    real_features: np.ndarray,
    real_labels: np.ndarray,
    epochs: int,
    sigma_d: float = 0.45,
    sigma_g: float = 0.8,
    max_phase_steps: int = 25,
    noise_std: float = 0.1,
    batch_size: int = 50,
    lr: float = 2e-4,
    seed: int = 0,
    progress: bool = False,
) -> dict[str, list[float]]:
    """Algorithm 2: alternate D (until L_D / 2 < sigma_D) and G (until L_FC and L_D < sigma_G).

    Each step draws a batch of known classes' attribute vectors and a batch of real
    features f_ext = CONV_XF(x) (precomputed: CONV_XF is frozen here). Beyond the
    paper, a phase also ends after ``max_phase_steps`` updates so a threshold that
    is never reached cannot starve the other network.
    """
    gen = torch.Generator().manual_seed(seed)
    _frozen(fc_y)
    a_all = torch.as_tensor(attributes, dtype=torch.float32)
    f_real = torch.as_tensor(real_features, dtype=torch.float32)
    y_real = torch.as_tensor(real_labels, dtype=torch.long)
    opt_g = torch.optim.Adam(generator.parameters(), lr=lr, betas=(0.5, 0.999))
    opt_d = torch.optim.Adam(discriminator.parameters(), lr=lr, betas=(0.5, 0.999))
    bce = nn.BCEWithLogitsLoss()
    ce = nn.CrossEntropyLoss()
    train_d, phase_steps = True, 0
    log: dict[str, list[float]] = {"loss_d": [], "loss_fc": [], "loss_g": [], "switches": []}
    generator.train()
    discriminator.train()
    n_batches = max(1, len(f_real) // batch_size)
    for _ in tqdm(
        range(epochs), desc="G and D, Algorithm 2", disable=bar_disabled(progress), leave=False
    ):
        order = torch.randperm(len(f_real), generator=gen)
        for b in range(n_batches):
            real_idx = order[b * batch_size : (b + 1) * batch_size]
            # class attributes paired with the real batch's labels keep classes balanced
            # with the data
            y = y_real[real_idx]
            a = noisy(a_all[y], noise_std, gen)
            phase_steps += 1
            if train_d:
                opt_d.zero_grad()
                fake = generator(a).detach()
                loss_d = bce(discriminator(fake), torch.zeros(len(fake))) + bce(
                    discriminator(f_real[real_idx]), torch.ones(len(real_idx))
                )
                loss_d.backward()
                opt_d.step()
                log["loss_d"].append(loss_d.item())
                if loss_d.item() / 2 < sigma_d or phase_steps >= max_phase_steps:
                    train_d, phase_steps = False, 0
                    log["switches"].append(len(log["loss_d"]) + len(log["loss_g"]))
            else:
                opt_g.zero_grad()
                loss_fc = ce(fc_y(generator(a)), y)
                loss_fc.backward()
                opt_g.step()
                opt_g.zero_grad()
                loss_g = bce(discriminator(generator(a)), torch.ones(len(a)))
                loss_g.backward()
                opt_g.step()
                log["loss_fc"].append(loss_fc.item())
                log["loss_g"].append(loss_g.item())
                if (
                    loss_fc.item() < sigma_g and loss_g.item() < sigma_g
                ) or phase_steps >= max_phase_steps:
                    train_d, phase_steps = True, 0
                    log["switches"].append(len(log["loss_d"]) + len(log["loss_g"]))
    generator.eval()
    discriminator.eval()
    return log
