"""Compare two renders channel group by channel group, with thresholds in
the style of OpenImageIO's `idiff`, and draw their differences.

Groups, their channels and the per-pixel error each is judged by:
  colour    R,G,B                     max over R,G,B of |a - b| (linear values); reported:
                                      RMSE, PSNR (peak 1), max abs, mean FLIP (LDR FLIP of
                                      OpenImageIO on RGB clipped to [0,1]; None without it)
  coverage  A                         1 where exactly one image has the surface (A > 0)
  depth     Z                         |Za - Zb| / min(Za, Zb), where both have the surface
  normals   N.X,N.Y,N.Z               angle between the normals in degrees, where both have
                                      the surface
  ids       level,patch_id,object_id  1 where any id differs, where both have the surface
  position  P.X,P.Y,P.Z               |Pa - Pb| / min(Za, Zb) (relative to the distance from
                                      the eye, as depth; world units without Z), where both
                                      have the surface
Colour and coverage are judged over all pixels, the others over the pixels covered in both
(by their centre rays: a finite depth where the images have one)
(coverage differences are counted once, by coverage). A group is compared when both images
have all of its channels; one image having a group that the other lacks is a mismatch,
except for the optional groups (OPTIONAL_GROUPS: position), which are then left out.

Pictures of the differences: the heat map (:meth:`Comparison.heat`, :func:`heat_map`) shows
each pixel's largest error over its group's fail threshold, over every group but ids; ids
are labels, not quantities, so they are judged by the count of pixels whose ids changed and
drawn as a map of their own (:meth:`Comparison.ids_changed`, :func:`ids_map`).

Verdict of a group (idiff's rule, per group): n_fail pixels have error > fail, n_warn have
error > warn; FAIL when n_fail > failpercent % of the group's pixels or the largest error
> hardfail; else WARN when n_warn > warnpercent % of them; else PASS. The image's verdict
is the worst group's. Exit codes (idiff's): 0 pass, 1 warn, 2 fail, 3 size or channel
mismatch, 4 a file that cannot be read.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import numpy as np
import OpenImageIO as oiio

from subtrace.errors import SubtraceError
from subtrace.io.exr import read_exr, write_exr, write_png

PASS, WARN, FAIL = "pass", "warn", "fail"
EXIT_CODES = {PASS: 0, WARN: 1, FAIL: 2}
EXIT_MISMATCH = 3
EXIT_UNREADABLE = 4

GROUPS = {
    "colour": ("R", "G", "B"),
    "coverage": ("A",),
    "depth": ("Z",),
    "normals": ("N.X", "N.Y", "N.Z"),
    "ids": ("level", "patch_id", "object_id"),
    "position": ("P.X", "P.Y", "P.Z"),
}
# the groups of the heat map: all but the ids (labels: a changed id has no size)
HEAT_GROUPS = tuple(g for g in GROUPS if g != "ids")
# groups compared only when both images have them (images written before subtrace wrote
# P, or by other renderers, still compare)
OPTIONAL_GROUPS = frozenset(("position",))


class ImageMismatchError(SubtraceError):
    """The two images differ in size or in the channel groups they hold (exit code 3)."""


class UnreadableImageError(SubtraceError):
    """An image file is missing or cannot be read (exit code 4)."""


@dataclass(frozen=True)
class Thresholds:
    """idiff-style thresholds of one group (errors in the group's unit; percents of its
    pixels). ``hardfail``: any single pixel above it fails (inf: never)."""

    warn: float
    fail: float
    warnpercent: float = 0.0
    failpercent: float = 0.0
    hardfail: float = math.inf


# Defaults, for renders of the same scene by the same (deterministic) renderer, so that
# float noise from harmless code changes passes and real changes do not:
# colour: 0.02 (5 sRGB codes in the mid-tones), up to 1 % of the pixels may exceed it (the
#   silhouette pixels that flip between surface and background);
# coverage: any flip counts; 0.5 % of the pixels may flip (a silhouette shifted by a fraction
#   of a pixel) before a failure, any flip is a warning;
# depth: 1e-3 relative, beyond what a one-pixel tolerance moves a surface at normal incidence
#   (about 2e-5 relative) but below a change of the shape; 1 % may exceed (grazing pixels);
# normals: 2 degrees, 1 % may exceed (pixels beside creases and occlusion edges);
# ids: any difference counts; 1 % may differ (patch borders that a tiny shift crosses). A
#   change of refinement level changes `level` over whole patches and fails.
# position: as depth (the hit point moves along the ray by the depth's change, and a
#   sideways move of the same size is as large a change of the surface)
DEFAULT_THRESHOLDS = {
    "colour": Thresholds(warn=0.005, fail=0.02, warnpercent=0.1, failpercent=1.0),
    "coverage": Thresholds(warn=0.5, fail=0.5, warnpercent=0.0, failpercent=0.5),
    "depth": Thresholds(warn=1e-4, fail=1e-3, warnpercent=0.1, failpercent=1.0),
    "normals": Thresholds(warn=0.5, fail=2.0, warnpercent=0.1, failpercent=1.0),
    "ids": Thresholds(warn=0.5, fail=0.5, warnpercent=0.0, failpercent=1.0),
    "position": Thresholds(warn=1e-4, fail=1e-3, warnpercent=0.1, failpercent=1.0),
}
THRESHOLD_FIELDS = ("warn", "fail", "warnpercent", "failpercent", "hardfail")


@dataclass
class GroupResult:
    """One group's comparison: ``metrics`` (name -> number or None), pixel counts, verdict."""

    name: str
    pixels: int  # pixels judged (see the module comment)
    n_warn: int
    n_fail: int
    max_error: float
    thresholds: Thresholds
    verdict: str
    metrics: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "pixels": self.pixels,
            "n_warn": self.n_warn,
            "n_fail": self.n_fail,
            "max_error": _json_number(self.max_error),
            "thresholds": {k: _json_number(getattr(self.thresholds, k)) for k in THRESHOLD_FIELDS},
            **{k: _json_number(v) for k, v in self.metrics.items()},
        }


@dataclass
class Comparison:
    """The result of :func:`compare_images`: per-group results, the overall verdict and
    exit code, the per-pixel error maps (group -> (H,W) float32, 0 where not judged), the
    pixels where both images have the surface (``covered``: (H,W) bool, judged by depth,
    normals, ids and position) and both images' linear RGB (``rgb``: a pair of (H,W,3)
    float32, None without colour channels) for pictures."""

    width: int
    height: int
    groups: dict
    errors: dict
    verdict: str
    covered: np.ndarray | None = None
    rgb: tuple | None = None

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]

    def as_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "exit_code": self.exit_code,
            "width": self.width,
            "height": self.height,
            "groups": {name: g.as_dict() for name, g in self.groups.items()},
        }

    def table(self) -> str:
        """A readable report: one row per group, then the verdict."""
        rows = [("group", "verdict", "pixels", "> warn", "> fail", "max", "metrics")]
        for g in self.groups.values():
            metrics = ", ".join(f"{k} {format_value(v)}" for k, v in g.metrics.items())
            rows.append((g.name, g.verdict.upper(), str(g.pixels), str(g.n_warn), str(g.n_fail),
                         format_value(g.max_error), metrics))
        widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]) - 1)]
        lines = ["  ".join(c.ljust(w) for c, w in zip(r[:-1], widths)) + "  " + r[-1]
                 for r in rows]
        lines.append(f"{self.width}x{self.height}: {self.verdict.upper()}")
        return "\n".join(lines)

    def diff_channels(self) -> dict:
        """Difference image channels: |dR|,|dG|,|dB| as R,G,B, then each group's per-pixel
        error (``coverage``, ``depth_rel``, ``normal_deg``, ``ids``, ``position_rel``) and
        ``heat``: the largest error divided by its group's fail threshold (>= 1 fails), over
        the groups but ids (:data:`HEAT_GROUPS`; ``ids`` is 1 where an id changed)."""
        out = {c: self.errors[c] for c in ("R", "G", "B") if c in self.errors}
        names = {"coverage": "coverage", "depth": "depth_rel", "normals": "normal_deg",
                 "ids": "ids", "position": "position_rel"}
        for group, name in names.items():
            if group in self.groups:
                out[name] = self.errors[group]
        out["heat"] = self.heat()
        return out

    def heat(self, group: str | None = None) -> np.ndarray:
        """(H,W) float32: error / fail threshold of ``group``, or (None) the largest over
        :data:`HEAT_GROUPS` (0 where nothing differs; ids never count)."""
        heat = np.zeros((self.height, self.width), dtype=np.float32)
        for name, g in self.groups.items():
            if name == "ids" or group not in (None, name):
                continue
            scale = g.thresholds.fail if g.thresholds.fail > 0 else 1.0
            np.maximum(heat, self.errors[name] / np.float32(scale), out=heat)
        return heat

    def ids_changed(self) -> np.ndarray | None:
        """(H,W) bool: pixels covered in both images whose level, patch or object id
        changed; None when the ids group was not compared."""
        return self.errors["ids"] > 0 if "ids" in self.groups else None

    def write_diff(self, path, png_path=None) -> list:
        """Write :meth:`diff_channels` as an EXR (verdict in the header) and optionally a PNG
        heat map of :meth:`heat` (black: equal, red: half the fail threshold, yellow:
        at the threshold, white: twice it or more) and, when the ids were compared, the ids
        map beside it (``<png stem>_ids.png``, :func:`ids_map`), each with its colour key
        drawn in ``KEY_ROWS`` rows under the image's (:func:`with_key`). Returns the PNGs'
        paths."""
        attrs = {"compare_verdict": self.verdict}
        write_exr(path, self.diff_channels(), attrs)
        if png_path is None:
            return []
        write_png(png_path, with_key(heat_map(self.heat()), heat_key))
        changed = self.ids_changed()
        if changed is None:
            return [png_path]
        stem, ext = os.path.splitext(os.fspath(png_path))
        write_png(stem + "_ids" + ext, with_key(ids_map(changed, self.covered), ids_key))
        return [png_path, stem + "_ids" + ext]


def heat_map(heat: np.ndarray) -> np.ndarray:
    """(H,W) -> (H,W,3) float64 linear RGB ramp: 0 black, 0.5 red, 1 yellow, >= 2 white."""
    stops = np.array([0.0, 0.5, 1.0, 2.0])
    colours = np.array([[0, 0, 0], [0.8, 0, 0], [1, 0.85, 0], [1, 1, 1]], dtype=np.float64)
    h = np.nan_to_num(np.asarray(heat, dtype=np.float64), nan=2.0, posinf=2.0)
    return np.stack([np.interp(h, stops, colours[:, k]) for k in range(3)], axis=-1)


# ids map colours (linear RGB): no surface in one image or both, same ids, changed ids
IDS_COLOURS = {"not judged": (0.0, 0.0, 0.0), "same": (0.045, 0.045, 0.045),
               "changed": (1.0, 0.0, 0.9)}


def ids_map(changed: np.ndarray, covered: np.ndarray | None = None) -> np.ndarray:
    """(H,W) bool changed ids (and where both images have the surface) -> (H,W,3) float64
    linear RGB in :data:`IDS_COLOURS`: magenta changed, dark grey same, black not judged."""
    changed = np.asarray(changed, dtype=bool)
    covered = np.ones_like(changed) if covered is None else np.asarray(covered, dtype=bool)
    out = np.zeros((*changed.shape, 3))
    out[covered] = IDS_COLOURS["same"]
    out[changed] = IDS_COLOURS["changed"]
    return out


# the rows of the colour key under a heat or ids map's PNG (its image's rows come first)
KEY_ROWS = 44
KEY_BACKGROUND = 0.03  # linear grey: the key's black stands out from it
KEY_TEXT = 11  # pixels


def with_key(rgb: np.ndarray, key) -> np.ndarray:
    """(H,W,3) map -> (H + KEY_ROWS, W, 3): the map, then ``key(W)``'s rows under it."""
    return np.concatenate([rgb, key(rgb.shape[1])], axis=0)


def _labelled(band: np.ndarray, labels) -> np.ndarray:
    """``band`` (rows, W, 3) with the texts ``labels`` [(x, baseline y, text, "left" /
    "center" / "right")] drawn in white by OpenImageIO (its own font)."""
    buf = oiio.ImageBuf(np.ascontiguousarray(band, dtype=np.float32))
    for x, y, text, align in labels:
        oiio.ImageBufAlgo.render_text(buf, int(x), int(y), text, KEY_TEXT, "",
                                      (1.0, 1.0, 1.0), align)
    return np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float64).reshape(band.shape)


def heat_key(width: int) -> np.ndarray:
    """(KEY_ROWS, width, 3) linear RGB: the heat map's key, its ramp from 0 to 2
    (:func:`heat_map`) with the stops labelled, in units of each group's fail threshold."""
    band = np.full((KEY_ROWS, width, 3), KEY_BACKGROUND)
    x0, x1 = 4, max(width - 4, 5)
    band[4:14, x0:x1] = heat_map(np.linspace(0.0, 2.0, x1 - x0)[None, :])
    if width < 120:  # (too narrow for the labels: the ramp alone)
        return band
    at = lambda h: x0 + h / 2.0 * (x1 - x0 - 1)  # noqa: E731
    return _labelled(band, [(at(0.0), 27, "0", "left"), (at(0.5), 27, "0.5", "center"),
                            (at(1.0), 27, "1 fail", "center"), (at(2.0), 27, "2+", "right"),
                            (x0, 40, "error / fail threshold", "left")])


def ids_key(width: int) -> np.ndarray:
    """(KEY_ROWS, width, 3) linear RGB: the ids map's key, a swatch of each of
    :data:`IDS_COLOURS` with its name (the names left out where the map is too narrow)."""
    band = np.full((KEY_ROWS, width, 3), KEY_BACKGROUND)
    step = max(width // 3, 1)
    labels = []
    for k, (name, colour) in enumerate(IDS_COLOURS.items()):
        x = k * step + 4
        band[6:18, x:min(x + 12, width)] = 0.25  # (a frame, so that black shows)
        band[7:17, x + 1:min(x + 11, width)] = colour
        labels.append((x, 32, name, "left"))
    return band if width < 180 else _labelled(band, labels)


def compare_images(a, b, thresholds: dict | None = None, flip: bool = True,
                   aliases: dict | None = None, groups=None) -> Comparison:
    """Compare two images group by group (see the module comment).

    a, b: EXR paths (str or PathLike) or channel dicts (name -> (H,W) array, as
      ``read_exr`` or ``RenderResult.channels`` give). The comparison is symmetric except
      for FLIP, which takes ``b`` as the reference.
    thresholds: group -> Thresholds, or group -> dict of some of THRESHOLD_FIELDS replacing
      the defaults (DEFAULT_THRESHOLDS).
    flip: compute the mean FLIP of the colour group (needs OpenImageIO >= 3.2; None else).
    aliases: subtrace's channel name -> another renderer's (e.g. ``{"N": "Normal"}``: a
      name or a prefix before '.'): either image's channels of the other name are read as
      subtrace's.
    groups: the groups compared (default: every group); the others are neither compared
      nor required.
    Raises UnreadableImageError for a file that cannot be read, ImageMismatchError for
    different sizes or channel groups, SubtraceError for an unknown group or field.
    """
    limits = resolve_thresholds(thresholds)
    wanted = check_groups(GROUPS if groups is None else groups)
    ca, name_a = _channels(a, "A")
    cb, name_b = _channels(b, "B")
    ca, cb = rename_channels(ca, aliases or {}), rename_channels(cb, aliases or {})
    shape_a, shape_b = _shape(ca), _shape(cb)
    if shape_a != shape_b:
        raise ImageMismatchError(
            f"{name_a} is {shape_a[1]}x{shape_a[0]} but {name_b} is {shape_b[1]}x{shape_b[0]}"
        )
    present = []
    for group, names in GROUPS.items():
        if group not in wanted:
            continue
        has_a, has_b = _has_group(ca, names), _has_group(cb, names)
        if has_a != has_b and group not in OPTIONAL_GROUPS:
            with_it, without = (name_a, name_b) if has_a else (name_b, name_a)
            raise ImageMismatchError(
                f"{with_it} has the {group} channels {','.join(names)} but {without} has not"
            )
        if has_a and has_b:
            present.append(group)
    if not present:
        raise ImageMismatchError(
            f"{name_a} and {name_b} have no channel group in common (expected some of "
            f"{', '.join(','.join(n) for n in GROUPS.values())})"
        )

    height, width = shape_a
    f = lambda c, n: np.asarray(c[n], dtype=np.float64)  # noqa: E731
    # pixels with the surface: A > 0 where there is coverage, else a finite depth
    if "coverage" in present:
        cov_a, cov_b = f(ca, "A") > 0, f(cb, "A") > 0
    elif "depth" in present:
        cov_a, cov_b = np.isfinite(f(ca, "Z")), np.isfinite(f(cb, "Z"))
    else:
        cov_a = cov_b = np.ones((height, width), dtype=bool)
    both = cov_a & cov_b
    if "depth" in present:
        # depth, normals and ids come from each pixel's centre ray: judged where both
        # centre rays hit (anti-aliased alpha is above 0 where only other rays hit)
        both = np.isfinite(f(ca, "Z")) & np.isfinite(f(cb, "Z"))
    all_px = np.ones((height, width), dtype=bool)

    groups, errors = {}, {}
    for group in present:
        metrics = {}
        if group == "colour":
            d = [np.abs(f(ca, c) - f(cb, c)) for c in GROUPS["colour"]]
            for c, dc in zip(GROUPS["colour"], d):
                errors[c] = _finite_or_inf(dc).astype(np.float32)
            err, mask = _finite_or_inf(np.maximum.reduce(d)), all_px
            mse = float(np.mean(np.square(np.nan_to_num(np.stack(d), nan=np.inf))))
            metrics["rmse"] = math.sqrt(mse)
            metrics["psnr"] = (10.0 * math.log10(1.0 / mse) if 0 < mse < math.inf
                               else math.inf if mse == 0 else -math.inf)
            metrics["max_abs"] = float(err.max())
            metrics["mean_flip"] = _mean_flip(ca, cb) if flip else None
        elif group == "coverage":
            err, mask = (cov_a != cov_b).astype(np.float64), all_px
            metrics["count"] = int(err.sum())
        elif group == "depth":
            za, zb = f(ca, "Z"), f(cb, "Z")
            with np.errstate(invalid="ignore", divide="ignore"):
                rel = np.abs(za - zb) / np.minimum(np.abs(za), np.abs(zb))
            rel = np.where(za == zb, 0.0, rel)  # equal depths (0 and 0, inf and inf) agree
            err, mask = np.where(both, _finite_or_inf(rel), 0.0), both
            metrics["max_rel"] = float(err.max(initial=0.0))
            metrics["mean_rel"] = float(err[both].mean()) if both.any() else 0.0
        elif group == "normals":
            na = np.stack([f(ca, c) for c in GROUPS["normals"]], axis=-1)
            nb = np.stack([f(cb, c) for c in GROUPS["normals"]], axis=-1)
            err, mask = np.where(both, normal_angle_deg(na, nb), 0.0), both
            metrics["max_deg"] = float(err.max(initial=0.0))
            metrics["mean_deg"] = float(err[both].mean()) if both.any() else 0.0
        elif group == "position":
            pa = np.stack([f(ca, c) for c in GROUPS["position"]], axis=-1)
            pb = np.stack([f(cb, c) for c in GROUPS["position"]], axis=-1)
            dist = np.sqrt(np.square(pa - pb).sum(axis=-1))
            if "depth" in present:
                with np.errstate(invalid="ignore", divide="ignore"):
                    dist = dist / np.minimum(np.abs(f(ca, "Z")), np.abs(f(cb, "Z")))
            err, mask = np.where(both, _finite_or_inf(dist), 0.0), both
            metrics["max"] = float(err.max(initial=0.0))
            metrics["mean"] = float(err[both].mean()) if both.any() else 0.0
        else:  # ids
            differ = np.zeros((height, width), dtype=bool)
            for c in GROUPS["ids"]:
                differ |= f(ca, c) != f(cb, c)
            err, mask = (differ & both).astype(np.float64), both
            metrics["count"] = int(err.sum())
        errors[group] = err.astype(np.float32)
        groups[group] = _judge(group, err[mask], limits[group], metrics)
    worst = max((g.verdict for g in groups.values()), key=lambda v: EXIT_CODES[v])
    rgb = None
    if _has_group(ca, GROUPS["colour"]) and _has_group(cb, GROUPS["colour"]):
        rgb = tuple(np.stack([np.asarray(c[k], dtype=np.float32) for k in "RGB"], axis=-1)
                    for c in (ca, cb))
    return Comparison(width, height, groups, errors, worst, covered=both, rgb=rgb)


def normal_angle_deg(na: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Angle in degrees between (..., 3) vectors (atan2 of |a x b| and a.b: accurate for
    small angles); 180 where a vector is zero or not finite."""
    cross = np.linalg.norm(np.cross(na, nb), axis=-1)
    dot = np.sum(na * nb, axis=-1)
    with np.errstate(invalid="ignore"):
        angle = np.degrees(np.arctan2(cross, dot))
    bad = ~np.isfinite(angle) | ~(np.linalg.norm(na, axis=-1) > 0) | ~(
        np.linalg.norm(nb, axis=-1) > 0
    )
    return np.where(bad, 180.0, angle)


def resolve_thresholds(thresholds: dict | None) -> dict:
    """DEFAULT_THRESHOLDS with ``thresholds`` (group -> Thresholds or dict of fields) applied."""
    limits = dict(DEFAULT_THRESHOLDS)
    for group, value in (thresholds or {}).items():
        if group not in GROUPS:
            raise SubtraceError(
                f"unknown channel group {group!r}: use one of {', '.join(GROUPS)}"
            )
        if isinstance(value, Thresholds):
            limits[group] = value
            continue
        unknown = set(value) - set(THRESHOLD_FIELDS)
        if unknown:
            raise SubtraceError(
                f"unknown threshold {sorted(unknown)[0]!r}: use {', '.join(THRESHOLD_FIELDS)}"
            )
        for key, number in value.items():
            if not (isinstance(number, (int, float)) and number >= 0 and not math.isnan(number)):
                raise SubtraceError(f"{group} {key}: expected a number >= 0, got {number!r}")
        limits[group] = replace(limits[group], **{k: float(v) for k, v in value.items()})
    return limits


def _judge(group: str, err: np.ndarray, limits: Thresholds, metrics: dict) -> GroupResult:
    n = int(err.size)
    n_warn = int(np.count_nonzero(err > limits.warn))
    n_fail = int(np.count_nonzero(err > limits.fail))
    max_error = float(err.max(initial=0.0))
    if n_fail > limits.failpercent / 100.0 * n or max_error > limits.hardfail:
        verdict = FAIL
    elif n_warn > limits.warnpercent / 100.0 * n:
        verdict = WARN
    else:
        verdict = PASS
    return GroupResult(group, n, n_warn, n_fail, max_error, limits, verdict, metrics)


def check_groups(groups) -> tuple:
    """``groups`` as a tuple of group names; SubtraceError naming an unknown one."""
    groups = tuple(groups)
    for g in groups:
        if g not in GROUPS:
            raise SubtraceError(f"unknown channel group {g!r}: use one of {', '.join(GROUPS)}")
    return groups


def rename_channels(channels: dict, aliases: dict) -> dict:
    """``channels`` with each channel named (or prefixed ``name.``) as an alias's other name
    renamed to subtrace's (``aliases``: subtrace's name -> the other's)."""
    if not aliases:
        return channels
    out = {}
    for name, plane in channels.items():
        for ours, theirs in aliases.items():
            if name == theirs:
                name = ours
                break
            if name.startswith(theirs + "."):
                name = ours + name[len(theirs):]
                break
        out[name] = plane
    return out


def _channels(image, label: str) -> tuple[dict, str]:
    """(channels, name for messages) of a path or a channel dict."""
    if isinstance(image, dict):
        return image, f"image {label}"
    path = os.fsdecode(os.fspath(image))
    try:
        channels, _ = read_exr(path)
    except SubtraceError as err:
        raise UnreadableImageError(str(err)) from None
    return channels, path


def _shape(channels: dict) -> tuple[int, int]:
    return np.shape(next(iter(channels.values()))) if channels else (0, 0)


def _has_group(channels: dict, names) -> bool:
    return all(n in channels for n in names)


def _finite_or_inf(x: np.ndarray) -> np.ndarray:
    """NaN errors (a NaN in one image) become +inf, so that they count as failures."""
    return np.where(np.isnan(x), np.inf, x)


def _mean_flip(ca: dict, cb: dict) -> float | None:
    """Mean LDR FLIP error of R,G,B clipped to [0,1], ``cb`` as the reference; None when
    OpenImageIO has no FLIP_diff."""
    flip_diff = getattr(oiio.ImageBufAlgo, "FLIP_diff", None)
    if flip_diff is None:
        return None

    def buf(channels):
        rgb = np.stack([np.asarray(channels[c], dtype=np.float32) for c in "RGB"], axis=-1)
        rgb = np.clip(np.nan_to_num(rgb, nan=0.0), 0.0, 1.0)
        image = oiio.ImageBuf(oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.FLOAT))
        image.set_pixels(oiio.ROI(), np.ascontiguousarray(rgb))
        return image

    result = flip_diff(buf(cb), buf(ca), hdr=0)
    if result.has_error:
        return None
    return float(result.spec().getattribute("FLIP:meanerror"))


def _json_number(v):
    """JSON has no infinities or NaN: those become strings."""
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return v


def format_value(v) -> str:
    """A table cell's text of a figure: ``n/a`` for none, integers as they are, floats to 4
    significant digits (the command line's table and the HTML page alike)."""
    if v is None:
        return "n/a"
    if isinstance(v, int):
        return str(v)
    return f"{v:.4g}"


__all__ = [
    "compare_images",
    "Comparison",
    "GroupResult",
    "Thresholds",
    "DEFAULT_THRESHOLDS",
    "GROUPS",
    "ImageMismatchError",
    "UnreadableImageError",
    "heat_map",
    "ids_map",
    "HEAT_GROUPS",
    "normal_angle_deg",
]
