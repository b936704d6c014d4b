"""PNG plots for reports (matplotlib, headless). Each function writes one file atomically."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed; must precede pyplot
import matplotlib.pyplot as plt  # noqa: E402

from recon.workspace import atomic_output  # noqa: E402


def _save(fig: plt.Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight", format="png")
    plt.close(fig)
    return path


def pair_focals(
    path: Path,
    focals_px: Sequence[float | None],
    statuses: Sequence[str],
    *,
    truth_px: float | None,
    fused_px: float | None,
    title: str,
) -> Path:
    """Per-pair focal estimates (one dot per pair, coloured by status) with truth and fusion."""
    fig, ax = plt.subplots(figsize=(8, 4))
    kinds = sorted(set(statuses))
    for kind in kinds:
        idx = [i for i, s in enumerate(statuses) if s == kind and focals_px[i] is not None]
        ax.scatter(idx, [focals_px[i] for i in idx], s=14, label=f"{kind} ({len(idx)})")
    if truth_px is not None:
        ax.axhline(truth_px, color="black", lw=1, label=f"truth {truth_px:.1f} px")
    if fused_px is not None:
        ax.axhline(fused_px, color="tab:red", lw=1, ls="--", label=f"fused {fused_px:.1f} px")
    ax.set_xlabel("image pair")
    ax.set_ylabel("focal length (px)")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return _save(fig, path)


def method_errors(path: Path, rel_errors: Mapping[str, float | None], *, title: str) -> Path:
    """Absolute relative focal error per method, in percent (log scale)."""
    names = [n for n, e in rel_errors.items() if e is not None]
    values = [max(abs(rel_errors[n]) * 100, 1e-4) for n in names]  # type: ignore[arg-type]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    bars = ax.bar(names, values, color="tab:blue")
    ax.bar_label(bars, labels=[f"{v:.2f}%" for v in values], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("|focal error| (%)")
    ax.set_title(title)
    ax.tick_params(axis="x", labelrotation=20)
    return _save(fig, path)


def error_curves(
    path: Path,
    x: Sequence[float],
    curves: Mapping[str, Sequence[float]],
    *,
    xlabel: str,
    ylabel: str,
    title: str,
) -> Path:
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, ys in curves.items():
        ax.plot(x, ys, marker="o", ms=3, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(title)
    ax.legend(fontsize=8)
    return _save(fig, path)


def principal_points(
    path: Path,
    points_px: Mapping[str, Sequence[float]],
    *,
    truth_px: Sequence[float] | None,
    image_size: tuple[int, int] | None,
    title: str,
) -> Path:
    """Each method's principal point (x right, y down, in px) with the truth and the centre."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for name, (x, y) in points_px.items():
        ax.scatter([x], [y], s=30, label=f"{name} ({x:.1f}, {y:.1f})")
    if truth_px is not None:
        ax.scatter([truth_px[0]], [truth_px[1]], marker="x", s=80, color="black",
                   label=f"truth ({truth_px[0]:.1f}, {truth_px[1]:.1f})")
    if image_size is not None:
        ax.scatter([image_size[0] / 2], [image_size[1] / 2], marker="+", s=80, color="grey",
                   label="image centre")
    ax.invert_yaxis()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("cx (px)")
    ax.set_ylabel("cy (px)")
    ax.set_title(title)
    ax.legend(fontsize=7)
    return _save(fig, path)
