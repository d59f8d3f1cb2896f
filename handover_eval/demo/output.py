"""The demo's files, each through the writers of :mod:`handover_eval.reporting`.

In ``out`` (default ``outputs/demo/``):

* ``demo_side_by_side.mp4``: the filmed walker, dynamic left, static right (15 fps, real time);
* ``demo_side_by_side.png``: one still of it, at the dynamic side's release
  (:func:`handover_eval.demo.report.still_index`);
* ``demo_summary.md``: the summary and per-walker tables (:func:`.report.summary_markdown`);
* ``demo_summary.csv`` (one row per side) and ``demo_episodes.csv`` (one row per episode).

The mp4 is encoded by imageio's ffmpeg (the ``[video]`` extra) into a private temporary folder,
then written to ``out`` as one atomic write.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from handover_env.extras import missing_extra
from handover_eval.demo.report import (
    episode_rows,
    side_by_side,
    still_index,
    summary,
    summary_markdown,
)
from handover_eval.demo.run import DemoRun
from handover_eval.reporting import atomic_write_bytes, write_csv, write_png, write_text

VIDEO_FPS = 15
VIDEO = "demo_side_by_side.mp4"
STILL = "demo_side_by_side.png"


def write_video(frames: Iterable[np.ndarray], path: Path, fps: int = VIDEO_FPS) -> Path:
    """Encode ``frames`` (equal-sized RGB uint8 arrays with even sides, as H.264's 4:2:0 needs;
    imageio would otherwise scale them) as an H.264 mp4 at ``path``."""
    try:
        import imageio.v2 as imageio
    except ModuleNotFoundError as exc:
        raise missing_extra("video", exc, __name__) from None
    with tempfile.TemporaryDirectory() as tmp:
        local = Path(tmp) / "video.mp4"
        with imageio.get_writer(local, fps=fps, codec="libx264", quality=7,
                                macro_block_size=2) as w:
            for frame in frames:
                w.append_data(frame)
        return atomic_write_bytes(path, local.read_bytes())


def write_image(image: np.ndarray, path: Path) -> Path:
    """``image`` (H, W, 3) uint8 as a PNG of exactly its pixels."""
    import matplotlib.pyplot as plt

    h, w = image.shape[:2]
    dpi = 100
    fig = plt.figure(figsize=(w / dpi, h / dpi), dpi=dpi)
    fig.figimage(image, xo=0, yo=0, origin="upper")
    return write_png(fig, path, dpi=dpi)


def write(run: DemoRun, out: Path) -> list[Path]:
    """Every file of the demo; the video and the still only for its filmed walkers (the first
    walker filmed on both sides)."""
    paths = [
        write_text(summary_markdown(run), out / "demo_summary.md"),
        write_csv(summary(run), out / "demo_summary.csv"),
        write_csv(episode_rows(run), out / "demo_episodes.csv"),
    ]
    dyn, sta = run.episodes["dynamic"], run.episodes["static"]
    filmed = [(d, s) for d, s in zip(dyn, sta) if d.frames and s.frames]
    if filmed:
        d, s = filmed[0]
        pick, still = still_index(d), []

        def frames() -> Iterable[np.ndarray]:
            for k, frame in enumerate(side_by_side(d, s)):
                if k == pick:
                    still.append(frame)
                yield frame

        paths.append(write_video(frames(), out / VIDEO))
        paths.append(write_image(still[0], out / STILL))
    return paths
