"""The generic figures of the evaluation reports, drawn with matplotlib (Agg, no display).

``plt()`` sets matplotlib up and returns ``matplotlib.pyplot``; the protocols' own figures
(``touches.plot_touches``, ``procedures.plot_procedures``, ``raw_report.plot_raw_accuracy``)
draw with it. This module imports no protocol and no report.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from app.evaluation.metrics import jaccard_similarity, row_normalize


def plt():
    """``matplotlib.pyplot`` on the Agg backend (imported on first use: matplotlib is slow
    to import and only the figures need it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot

    return matplotlib.pyplot


def plot_tuning_curve(curve: dict[str, Any], path: Path, title: str) -> None:
    pyplot = plt()
    fig, ax = pyplot.subplots(figsize=(6.4, 4.2), dpi=120)
    t = np.asarray(curve["thresholds"], dtype=float)
    ax.plot(t, curve["known_kept"], color="tab:blue", label="held-out known trials called known")
    ax.plot(t, curve["val_novel"], color="tab:red", label="validation-novel objects called novel")
    ax.plot(
        t,
        (np.asarray(curve["known_kept"]) + np.asarray(curve["val_novel"])) / 2,
        color="0.5",
        linestyle=":",
        label="mean (maximised)",
    )
    ax.axvline(
        curve["threshold"],
        color="k",
        linestyle="--",
        label=f"chosen threshold {curve['threshold']:.3g}",
    )
    ax.set_xlabel("novelty threshold (score above = novel)")
    ax.set_ylabel("accuracy")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(title)
    ax.legend(loc="center right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    pyplot.close(fig)


def _matrix_panel(
    ax,
    matrix: np.ndarray,
    labels: list[str],
    title: str,
    vmax: float = 1.0,
    xlabel: str = "predicted",
    ylabel: str = "true",
    ylabels: bool = True,
) -> Any:
    im = ax.imshow(matrix, cmap="Blues", vmin=0, vmax=vmax)
    n = len(labels)
    ax.set_xticks(range(n), labels, rotation=45, ha="right", fontsize=7)
    ax.set_yticks(range(n), labels if ylabels else [""] * n, fontsize=7)
    fontsize = 8 if n <= 8 else 6
    for i in range(n):
        for j in range(n):
            v = matrix[i, j]
            ax.text(
                j,
                i,
                f"{v:.2f}",
                ha="center",
                va="center",
                fontsize=fontsize,
                color="white" if v > 0.6 * vmax else "black",
            )
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    return im


def plot_confusions(
    panels: list[tuple[str, np.ndarray]], labels: list[str], path: Path, title: str
) -> None:
    pyplot = plt()
    n = len(labels)
    size = max(3.6, 0.45 * n + 1.6)
    fig, axes = pyplot.subplots(
        1,
        len(panels),
        figsize=(size * len(panels) + 1.5, size + 1.4),
        dpi=120,
        squeeze=False,
        layout="constrained",
    )
    im = None
    for i, (ax, (name, cm)) in enumerate(zip(axes[0], panels, strict=True)):
        im = _matrix_panel(
            ax,
            row_normalize(np.asarray(cm)),
            labels,
            name,
            ylabel="true" if i == 0 else "",
            ylabels=i == 0,
        )
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8, label="fraction of the true class")
    fig.suptitle(title, fontsize=10)
    fig.savefig(path, bbox_inches="tight")
    pyplot.close(fig)


def plot_jaccard(vectors: np.ndarray, labels: list[str], path: Path, title: str) -> None:
    pyplot = plt()
    n = len(labels)
    size = max(3.6, 0.45 * n + 1.6)
    fig, ax = pyplot.subplots(figsize=(size + 0.8, size + 0.4), dpi=120)
    im = _matrix_panel(ax, jaccard_similarity(vectors), labels, title, xlabel="", ylabel="")
    fig.colorbar(im, ax=ax, shrink=0.8, label="Jaccard similarity of attribute vectors")
    fig.savefig(path, bbox_inches="tight")
    pyplot.close(fig)
