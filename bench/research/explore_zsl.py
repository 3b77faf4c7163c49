"""Exploration bench: zero-shot alternatives against best's DAP, dev seeds only.

Approaches (``--approaches``, comma-separated), each reported alone and as a product
ensemble with DAP (``best``'s zero-shot), on the novel objects' held-out trials of
development split seeds (never seed 0, the reported one):

- ``fclswgan`` (Xian et al., 2018): a conditional WGAN-GP generator G(noise, attributes)
  -> scaled PHAC-2 features, trained on the known objects with an extra classification
  loss through a frozen softmax classifier of the known classes; G then synthesises
  features of the novel objects from their attribute vectors and a softmax classifier
  is trained on them.
- ``eszsl``: the ESZSL baseline (``app/baselines/eszsl.py``, validation-tuned).

    .venv/bin/python bench/research/explore_zsl.py --approaches fclswgan --seeds 1,2 --novel 6 --beta 0.01
    .venv/bin/python bench/research/explore_zsl.py --approaches eszsl --seeds 1,2 --novel 6
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F
from dev_splits import add_split_arguments, splits, tiny
from torch import nn

from app.data.phac2 import load_phac2
from app.evaluation.protocol import make_recognizer
from app.methods.known import flatten


class Generator(nn.Module):
    """(attributes A, noise Z) -> features D."""

    def __init__(self, n_attributes: int, n_noise: int, n_features: int, hidden: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(n_attributes + n_noise, hidden),
            nn.LeakyReLU(0.2),
            nn.Linear(hidden, n_features),
        )

    def forward(self, a: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([a, z], 1))


class Critic(nn.Module):
    """(features D, attributes A) -> Wasserstein critic score."""

    def __init__(self, n_features: int, n_attributes: int, hidden: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(n_features + n_attributes, hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, 1)
        )

    def forward(self, x: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([x, a], 1))


def softmax_classifier(x: torch.Tensor, y: torch.Tensor, k: int, epochs: int = 300) -> nn.Linear:
    lin = nn.Linear(x.shape[1], k)
    opt = torch.optim.Adam(lin.parameters(), 1e-2, weight_decay=1e-3)
    for _ in range(epochs):
        opt.zero_grad()
        F.cross_entropy(lin(x), y).backward()
        opt.step()
    return lin


def fclswgan(z, y, class_attributes, novel_attributes, seed: int, args) -> nn.Linear:
    torch.manual_seed(seed)
    x, yt = torch.tensor(z, dtype=torch.float32), torch.tensor(y)
    attrs = torch.tensor(class_attributes, dtype=torch.float32)
    known = softmax_classifier(x, yt, len(attrs))
    known.requires_grad_(False)
    g = Generator(attrs.shape[1], args.noise, x.shape[1], args.hidden)
    d = Critic(x.shape[1], attrs.shape[1], args.hidden)
    opt_g = torch.optim.Adam(g.parameters(), args.lr, betas=(0.5, 0.999))
    opt_d = torch.optim.Adam(d.parameters(), args.lr, betas=(0.5, 0.999))
    bs = 64
    for _ in range(args.iters):
        for _ in range(5):  # critic steps per generator step, WGAN-GP with lambda = 10
            i = torch.randint(0, len(x), (bs,))
            real, a = x[i], attrs[yt[i]]
            fake = g(a, torch.randn(bs, args.noise)).detach()
            eps = torch.rand(bs, 1)
            mix = (eps * real + (1 - eps) * fake).requires_grad_(True)
            grad = torch.autograd.grad(d(mix, a).sum(), mix, create_graph=True)[0]
            loss_d = (
                d(fake, a).mean() - d(real, a).mean() + 10 * ((grad.norm(dim=1) - 1) ** 2).mean()
            )
            opt_d.zero_grad()
            loss_d.backward()
            opt_d.step()
        i = torch.randint(0, len(x), (bs,))
        a = attrs[yt[i]]
        fake = g(a, torch.randn(bs, args.noise))
        loss_g = -d(fake, a).mean() + args.beta * F.cross_entropy(known(fake), yt[i])
        opt_g.zero_grad()
        loss_g.backward()
        opt_g.step()
    novel = torch.tensor(novel_attributes, dtype=torch.float32)
    with torch.no_grad():
        ys = torch.arange(len(novel)).repeat_interleave(args.synthetic)
        xs = g(novel[ys], torch.randn(len(ys), args.noise))
    return softmax_classifier(xs, ys, len(novel))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_split_arguments(p)
    p.add_argument("--approaches", default="fclswgan", help="fclswgan and/or eszsl")
    p.add_argument("--iters", type=int, default=2000, help="generator steps")
    p.add_argument("--beta", type=float, default=0.01, help="weight of the classification loss")
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--noise", type=int, default=24)
    p.add_argument(
        "--synthetic", type=int, default=200, help="features synthesised per novel class"
    )
    p.add_argument("--lr", type=float, default=1e-4)
    args = tiny(p.parse_args(), iters=5, hidden=32, synthetic=10)
    torch.set_num_threads(1)
    data = load_phac2(args.data)
    rows = []
    for seed, split in splits(data, args):
        t = time.perf_counter()
        train = split.train_dataset(data)
        best = make_recognizer("best", {"sae_lambda": 0}, 0).fit(train)  # its DAP part alone
        xn = data.samples[split.novel_test_idx]
        yn = split.novel_labels(data, split.novel_test_idx)
        vectors = split.novel_attributes(data)
        p_dap = best.add_novel_classes(
            list(split.novel_names), vectors, allow_known_vectors=True
        ).novel_proba(xn)
        row = {"seed": seed, "split": split.index + 1, "dap": float((p_dap.argmax(1) == yn).mean())}
        for approach in args.approaches.split(","):
            if approach == "fclswgan":
                cues = best.known_.cues_model
                clf = fclswgan(
                    cues.scaled(flatten(train.samples)),
                    train.labels,
                    train.class_attributes,
                    vectors,
                    seed * 100 + split.index,
                    args,
                )
                with torch.no_grad():
                    p = F.softmax(clf(torch.tensor(cues.scaled(flatten(xn)))), 1).numpy()
            elif approach == "eszsl":
                p = (
                    make_recognizer("eszsl", None, 0)
                    .fit(train)
                    .add_novel_classes(list(split.novel_names), vectors, allow_known_vectors=True)
                    .novel_proba(xn)
                )
            else:
                raise SystemExit(f"unknown approach {approach!r}")
            product = np.log(p_dap + 1e-12) + np.log(p + 1e-12)
            row[approach] = float((p.argmax(1) == yn).mean())
            row[f"dap*{approach}"] = float((product.argmax(1) == yn).mean())
        row["seconds"] = round(time.perf_counter() - t, 1)
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    mean = {
        k: round(float(np.mean([r[k] for r in rows])), 3)
        for k in rows[0]
        if k not in ("seed", "split", "seconds")
    }
    options = {k: str(v) for k, v in vars(args).items()}
    print(json.dumps({"zsl_mean": mean, "splits_run": len(rows), **options}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
