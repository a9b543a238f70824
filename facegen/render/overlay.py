"""Captions of the compare video, drawn once with Pillow: the names of A and B, the error colour bar.

The text is Pillow's default font (scalable, FreeType) in a size that follows the view size, anti-aliased
over the video's background colour: the caption pixels replace the frame's where the text or bar is.
"""

from __future__ import annotations

import numpy as np

from facegen.render.raster import BACKGROUND, heat_colors

TEXT = (0.85, 0.86, 0.88)  # sRGB


def compare_overlay(
    size: int, views: int, vmax: float, face_size: float, labels: tuple[str, str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The compare video's captions: pixel rows, columns and their RGB colours (uint8), for frames
    [size, 2 * size * views, 3].

    A title strip names A and B at the top of each half (cut to fit the half); a line at the bottom of B's
    half shows the colour bar and its scale: "|A-B|  0 [bar] 0.0123 = 0.92% of face size".
    """
    from PIL import Image, ImageDraw, ImageFont

    scale = max(1, size // 256)
    half, pad, line = size * views, 4 * scale, 10 * scale  # line: the text's height in pixels
    font = ImageFont.load_default(size=line)
    background = _rgb(BACKGROUND)
    image = Image.new("RGB", (2 * half, size), background)
    draw = ImageDraw.Draw(image)
    text = {"font": font, "fill": _rgb(TEXT)}
    for left, label in ((pad, labels[0]), (half + pad, labels[1])):
        draw.text((left, pad), _fit(label, font, half - 2 * pad), anchor="lt", **text)
    middle = size - pad - line // 2  # the bottom line's vertical centre
    top = f"{_short(vmax)} = {100 * vmax / face_size:.2g}% of face size" if face_size > 0 else _short(vmax)
    draw.text((half + pad, middle), "|A-B|  0", anchor="lm", **text)
    left = half + pad + round(draw.textlength("|A-B|  0", font=font)) + 2 * scale
    right = 2 * half - pad - round(draw.textlength(top, font=font))
    draw.text((2 * half - pad, middle), top, anchor="rm", **text)
    canvas = np.asarray(image).copy()
    drawn = (canvas != background).any(-1)
    right -= 3 * scale
    if right - left > 8:
        rows = slice(middle - 3 * scale, middle + 3 * scale)
        ramp = heat_colors(np.linspace(0, 1, right - left), 1.0)
        canvas[rows, left:right] = (ramp * 255 + 0.5).astype(np.uint8)[None]
        drawn[rows, left:right] = True
    ys, xs = np.nonzero(drawn)
    return ys, xs, canvas[ys, xs]


def _fit(text: str, font, width: float) -> str:
    """`text` cut at the end to fit `width` pixels."""
    while text and font.getlength(text) > width:
        text = text[:-1]
    return text


def _rgb(color: tuple[float, float, float]) -> tuple[int, int, int]:
    return tuple(int(c * 255 + 0.5) for c in color)


def _short(value: float) -> str:
    return f"{value:.3g}"
