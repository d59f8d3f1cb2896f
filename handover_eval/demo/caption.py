"""Captions drawn onto the demo's frames: what each side's caption says, and the drawing.

A side's caption has three lines: the agent; the time since the reset and the measured wrist
force (with the release threshold f_r, paper Sec. IV-C); and the state of the handover: the static
robot waiting for the raised hand and the 2 s stabilisation delay, the release once it happened,
and at the end the benchmark's outcome (``success`` with the handover time; otherwise the outcome
and the first failure as the benchmark charges it, :mod:`handover_eval.benchmark.outcomes`).

Text is drawn with Pillow (matplotlib's own dependency) in matplotlib's bundled DejaVu Sans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from handover_eval.demo.run import Moment

INK = (235, 235, 235)
GOOD = (110, 215, 120)
BAD = (255, 120, 100)
BAND = (28, 30, 36)
TITLE_BAND = (14, 15, 18)


@dataclass(frozen=True)
class CaptionStyle:
    """Pixels of the caption band and its fonts."""

    band_height: int = 100
    title_height: int = 40
    font_px: int = 21
    title_px: int = 20
    margin: int = 12


STYLE = CaptionStyle()


@lru_cache(maxsize=8)
def _font(px: int, bold: bool) -> Any:
    from matplotlib import font_manager
    from PIL import ImageFont

    path = font_manager.findfont(
        font_manager.FontProperties(family="DejaVu Sans", weight="bold" if bold else "normal")
    )
    return ImageFont.truetype(path, px)


def status_line(m: Moment, row: dict[str, Any] | None) -> tuple[str, tuple[int, int, int]]:
    """The caption's third line and its colour: ``row`` (the benchmark's scoring of the episode)
    once the episode has ended, else the handover's state at ``m``."""
    if row is not None:
        if row["success"]:
            return f"success: handover time {float(row['handover_time']):.2f} s", GOOD
        return f"{row['outcome']}  (first failure: {row['first_failure']})", BAD
    if not m.robot_enabled:
        return "robot waits: raised hand detected + 2 s", INK
    if m.release_time is not None:
        return f"released at {m.release_time:.2f} s", INK
    return "handing over ...", INK


def caption_lines(label: str, m: Moment, row: dict[str, Any] | None,
                  release_force: float) -> list[tuple[str, tuple[int, int, int], bool]]:
    """(text, colour, bold) of each caption line at moment ``m``."""
    force = "-" if not math.isfinite(m.wrist_force) else f"{m.wrist_force:5.1f} N"
    text, colour = status_line(m, row)
    return [
        (label, INK, True),
        (f"t = {m.time:5.2f} s    wrist force {force} (opens above {release_force:g} N)",
         INK, False),
        (text, colour, True),
    ]


@lru_cache(maxsize=256)
def _text_mask(text: str, px: int, bold: bool) -> Any:
    """``text`` drawn once as a greyscale mask (the labels and outcomes repeat every frame)."""
    from PIL import Image, ImageDraw

    font = _font(px, bold)
    left, top, right, bottom = font.getbbox(text)
    mask = Image.new("L", (max(right, 1), max(bottom, 1)), 0)
    ImageDraw.Draw(mask).text((0, 0), text, fill=255, font=font)
    return mask


def panel(scene: np.ndarray, lines: list[tuple[str, tuple[int, int, int], bool]],
          style: CaptionStyle = STYLE) -> np.ndarray:
    """``scene`` (H, W, 3) with the caption band (``style.band_height`` px) below it."""
    from PIL import Image

    h, w = scene.shape[:2]
    img = Image.new("RGB", (w, h + style.band_height), BAND)
    img.paste(Image.fromarray(scene), (0, 0))
    step = (style.band_height - 2 * 6) // max(len(lines), 1)
    for k, (text, colour, bold) in enumerate(lines):
        mask = _text_mask(text, style.font_px, bold)
        img.paste(colour, (style.margin, h + 6 + k * step), mask)
    return np.asarray(img)


def title_bar(text: str, width: int, style: CaptionStyle = STYLE) -> np.ndarray:
    """A ``style.title_height`` px band across ``width`` px with ``text``."""
    from PIL import Image, ImageDraw

    img = Image.new("RGB", (width, style.title_height), TITLE_BAND)
    draw = ImageDraw.Draw(img)
    font = _font(style.title_px, True)
    _, top, _, bottom = draw.textbbox((0, 0), text, font=font)
    draw.text((style.margin, (style.title_height - (bottom - top)) // 2 - top), text, fill=INK,
              font=font)
    return np.asarray(img)
