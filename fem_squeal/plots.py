"""Matplotlib figures (Agg backend, rank 0 only), saved atomically as PNG."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def contact_pressure(path: Path, data: dict[str, tuple[np.ndarray, np.ndarray]], title: str = "") -> None:
    """One panel per contact interface: the pressure [MPa] at the slave quadrature points,
    seen along the axis (x, y in mm), interpolated on their Delaunay triangulation."""
    from fem_squeal.output import save_figure_atomic

    plt = _pyplot()
    n = max(len(data), 1)
    fig, axes = plt.subplots(1, n, figsize=(5.0 * n, 4.2), squeeze=False)
    vmax = max((float(p.max()) for _, p in data.values() if len(p)), default=1.0) / 1e6 or 1.0
    for ax, (name, (x, p)) in zip(axes[0], data.items()):
        if len(p) >= 3:
            tc = ax.tricontourf(1e3 * x[:, 0], 1e3 * x[:, 1], p / 1e6, levels=np.linspace(0, vmax, 21),
                                cmap="viridis")
            fig.colorbar(tc, ax=ax, label="contact pressure [MPa]")
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_title(name)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    save_figure_atomic(fig, path)
    plt.close(fig)
