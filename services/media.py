"""Files of pictures: animations (GIF/MP4 through imageio) and evaluation heatmaps (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

VIDEO_SUFFIXES = (".gif", ".mp4")


def write_animation(frames: list[np.ndarray], path: Path, fps: float) -> Path:
    """Frames [H, W, 3] uint8 to a GIF (looping) or an MP4 (H.264 through imageio-ffmpeg)."""
    import imageio.v2 as imageio
    import imageio.v3 as iio

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"--out must end in one of {VIDEO_SUFFIXES}, got {path.name!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    stack = np.stack(frames)
    if suffix == ".gif":
        iio.imwrite(path, stack, duration=1000.0 / fps, loop=0)
    else:
        # H.264 wants even sizes
        h, w = stack.shape[1] // 2 * 2, stack.shape[2] // 2 * 2
        with imageio.get_writer(
            path, format="FFMPEG", fps=fps, codec="libx264", macro_block_size=1
        ) as writer:
            for frame in stack[:, :h, :w]:
                writer.append_data(frame)
    return path


def write_heatmap(grid: dict, path: Path, title: str) -> Path:
    """A [WL19] Fig. 6 style heatmap of per-parameter returns over two task dimensions, from
    the `grid` of an evaluation report (x, y, returns[y][x], fall[y][x])."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, y = np.array(grid["x"]), np.array(grid["y"])
    returns = np.array(grid["returns"])
    fig, ax = plt.subplots(figsize=(5.2, 4.2), dpi=110)
    mesh = ax.pcolormesh(x, y, returns, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="return")
    fall = np.array(grid.get("fall", np.zeros_like(returns)), dtype=bool)
    for j, i in zip(*np.nonzero(fall), strict=True):
        ax.text(x[i], y[j], "×", ha="center", va="center", color="white", fontsize=10)
    ax.set_xlabel(grid["dims"][0])
    ax.set_ylabel(grid["dims"][1])
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
