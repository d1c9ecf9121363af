"""Frames: a turntable camera path, frame ranges and numbered output names.

``subtrace render ... --turntable N`` renders N frames whose eyes orbit the target about the
camera's up axis through it, one full turn (frame k at 360 k / N degrees from the scene's
own eye, or from the automatic camera's); ``--frames A:B[:STEP]`` picks frames A, A+STEP,
... below B (Python's range; B may be left out: to the last frame). Outputs are numbered:
a run of ``#`` in the output name is the frame number padded to its length
(``spin.####.exr`` -> ``spin.0007.exr``), and a name without ``#`` gets ``.####`` before its
extension. One process renders every frame: the cages are read and checked once and the
kernels loaded once; each frame then builds what its view needs.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from subtrace.errors import SceneError

PAD = 4  # digits of a frame number when the output name has no '#'


def parse_frames(text: str | None, n_frames: int) -> range:
    """The frames ``A:B[:STEP]`` of ``n_frames`` (None: all); SceneError naming --frames."""
    if text is None:
        return range(n_frames)
    parts = text.split(":")
    try:
        if len(parts) == 1:
            a = int(parts[0])
            frames = range(a, a + 1)
        elif len(parts) in (2, 3):
            a = int(parts[0]) if parts[0] else 0
            b = int(parts[1]) if parts[1] else n_frames
            step = int(parts[2]) if len(parts) == 3 and parts[2] else 1
            if step <= 0:
                raise ValueError
            frames = range(a, b, step)
        else:
            raise ValueError
    except ValueError:
        raise SceneError(f"expected A:B[:STEP] (frame numbers, a step > 0), got {text!r}",
                         key="--frames") from None
    if not frames or frames.start < 0 or frames[-1] >= n_frames:
        raise SceneError(f"{text!r} selects no frames of 0..{n_frames - 1}", key="--frames")
    return frames


def frame_path(pattern: str, frame: int) -> str:
    """The output of ``frame``: the last run of '#' in the file name replaced by the frame
    number padded to its length, else ``.####`` inserted before the extension."""
    folder, name = os.path.split(pattern)
    runs = list(re.finditer(r"#+", name))
    if runs:
        m = runs[-1]
        name = f"{name[:m.start()]}{frame:0{len(m.group())}d}{name[m.end():]}"
    else:
        stem, ext = os.path.splitext(name)
        name = f"{stem}.{frame:0{PAD}d}{ext}"
    return os.path.join(folder, name)


def turntable_eye(eye, target, up, frame: int, n_frames: int) -> tuple:
    """The eye of turntable frame ``frame`` of ``n_frames``: ``eye`` turned about the axis
    through ``target`` along ``up`` by 360 frame / n_frames degrees (Rodrigues' formula)."""
    k = np.asarray(up, dtype=np.float64)
    k = k / np.linalg.norm(k)
    v = np.asarray(eye, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    a = 2.0 * math.pi * frame / n_frames
    turned = v * math.cos(a) + np.cross(k, v) * math.sin(a) + k * np.dot(k, v) * (1 - math.cos(a))
    return tuple(float(x) for x in np.asarray(target, dtype=np.float64) + turned)


def check_turntable(n) -> int:
    """--turntable N: a whole number of frames, at least 1."""
    try:
        value = int(n)
    except (TypeError, ValueError):
        value = 0
    if value < 1 or str(n).strip() != str(value):
        raise SceneError(f"expected a number of frames >= 1, got {n!r}", key="--turntable")
    return value


__all__ = ["parse_frames", "frame_path", "turntable_eye", "check_turntable"]
