"""Tests of subtrace.camera: frame conventions, pixel angle, auto camera, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from subtrace.errors import SceneError
from subtrace.camera import (
    AUTO_VIEW_DIRECTION,
    MAX_RESOLUTION,
    Camera,
    auto_camera,
    camera_frame,
    ray_direction,
)


def angle(a, b) -> float:
    """Angle between two vectors, accurate for small angles (atan2 of |a x b| and a.b)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b)))


def simple(width=101, height=75, fov=40.0) -> Camera:
    return Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov, width, height)


# --------------------------------------------------------------------------------------
# frame and rays
# --------------------------------------------------------------------------------------


def test_basis_looking_down_minus_z():
    right, up, forward = simple().basis()
    np.testing.assert_allclose(right, [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(up, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(forward, [0, 0, -1], atol=1e-15)


def test_basis_orthonormal_and_right_handed_camera_space():
    cam = Camera((1.0, 2.0, 3.0), (-2.0, 0.5, 1.0), (0.3, 1.0, -0.2), 50.0, 64, 48)
    right, up, forward = cam.basis()
    m = np.stack([right, up, forward])
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-15)
    # camera space (x right, y up, z = -forward) is right-handed
    np.testing.assert_allclose(np.cross(right, up), -forward, atol=1e-15)
    # the true up leans towards the given up
    assert np.dot(up, cam.up) > 0


def test_centre_pixel_of_odd_image_points_at_target():
    cam = Camera((1.0, 2.0, 3.0), (-2.0, 0.5, 1.0), (0.0, 1.0, 0.0), 35.0, 101, 75)
    d = cam.ray_directions()
    to_target = np.subtract(cam.target, cam.eye)
    # exact up to the rounding of a few float64 operations
    assert angle(d[37, 50], to_target) < 1e-14


def test_row_zero_is_top_and_column_zero_is_left():
    cam = simple(width=9, height=7)
    d = cam.ray_directions()
    # looking down -z with +y up: the top row goes up (+y), the left column goes -x
    assert np.all(d[0, :, 1] > 0) and np.all(d[-1, :, 1] < 0)
    assert np.all(d[:, 0, 0] < 0) and np.all(d[:, -1, 0] > 0)
    assert np.all(np.diff(d[:, 4, 1]) < 0)  # y decreases row by row
    assert np.all(np.diff(d[3, :, 0]) > 0)  # x increases column by column
    # the same with a tilted, off-axis camera, in its own basis
    cam = Camera((4.0, -1.0, 2.0), (0.0, 1.0, -1.0), (0.0, 0.0, 1.0), 60.0, 8, 6)
    right, up, _ = cam.basis()
    d = cam.ray_directions()
    assert np.all(d[0] @ up > 0) and np.all(d[-1] @ up < 0)
    assert np.all(d[:, 0] @ right < 0) and np.all(d[:, -1] @ right > 0)


def test_ray_directions_shape_dtype_unit():
    d = simple(width=13, height=5).ray_directions()
    assert d.shape == (5, 13, 3) and d.dtype == np.float64 and d.flags.c_contiguous
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, rtol=0, atol=1e-15)


def test_ray_directions_are_symmetric():
    d = simple(width=10, height=6).ray_directions()
    # mirror image about the vertical and the horizontal centre lines
    np.testing.assert_allclose(d[:, ::-1, 0], -d[:, :, 0], atol=1e-15)
    np.testing.assert_allclose(d[::-1, :, 1], -d[:, :, 1], atol=1e-15)


def test_jitted_ray_direction_matches_numpy_bit_for_bit():
    cam = Camera((1.0, 2.0, 3.0), (-2.0, 0.5, 1.0), (0.2, 1.0, 0.1), 47.0, 17, 11)
    frame = camera_frame(cam)
    assert frame.shape == (4, 3) and frame.dtype == np.float64 and frame.flags.c_contiguous
    np.testing.assert_array_equal(frame[0], cam.eye)
    d = cam.ray_directions()
    got = np.array(
        [[ray_direction(frame, float(r), float(c)) for c in range(17)] for r in range(11)]
    )
    np.testing.assert_array_equal(got, d)


def test_pixel_angle_formula():
    cam = simple(width=101, height=75, fov=40.0)
    expected = 2 * math.atan(math.tan(math.radians(40.0) / 2) / 75)
    assert cam.pixel_angle() == pytest.approx(expected, rel=1e-15)
    frame = camera_frame(cam)
    # the centre pixel (row 37, col 50) spans rows 36.5 .. 37.5 and cols 49.5 .. 50.5: the
    # angles between its edges equal the pixel angle (only rounding differs)
    top, bottom = ray_direction(frame, 36.5, 50.0), ray_direction(frame, 37.5, 50.0)
    left, right = ray_direction(frame, 37.0, 49.5), ray_direction(frame, 37.0, 50.5)
    assert angle(top, bottom) == pytest.approx(cam.pixel_angle(), rel=1e-12)
    assert angle(left, right) == pytest.approx(cam.pixel_angle(), rel=1e-12)
    # adjacent pixel centres: atan(s) vs 2 atan(s/2) differ by about s^3/4 (s = pixel size),
    # a relative 3e-5 here
    d = cam.ray_directions()
    s = cam.pixel_size()
    for a, b in ((d[37, 50], d[38, 50]), (d[37, 50], d[36, 50]), (d[37, 50], d[37, 51])):
        assert angle(a, b) == pytest.approx(math.atan(s), rel=1e-12)
        assert angle(a, b) == pytest.approx(cam.pixel_angle(), rel=s * s / 2)


def test_pixel_angle_scales_with_height_and_fov():
    assert simple(height=200).pixel_angle() < simple(height=100).pixel_angle()
    assert simple(fov=20).pixel_angle() < simple(fov=60).pixel_angle()
    # a 1-pixel-high image: the pixel is the whole field of view
    assert simple(height=1, fov=50).pixel_angle() == pytest.approx(math.radians(50), rel=1e-15)


def test_world_to_camera():
    """OpenEXR's camera space: the eye at the origin, the target straight ahead at +z (its
    distance), right and up along +x and +y."""
    cam = Camera((1.0, 2.0, 3.0), (-2.0, 0.5, 1.0), (0.0, 1.0, 0.0), 35.0, 10, 10)
    m = cam.world_to_camera()
    np.testing.assert_allclose(m @ [*cam.eye, 1.0], [0, 0, 0, 1], atol=1e-14)
    dist = float(np.linalg.norm(np.subtract(cam.target, cam.eye)))
    np.testing.assert_allclose(m @ [*cam.target, 1.0], [0, 0, dist, 1], atol=1e-14)
    right, up, _ = cam.basis()
    np.testing.assert_allclose(m @ [*(np.add(cam.eye, right)), 1.0], [1, 0, 0, 1], atol=1e-14)
    np.testing.assert_allclose(m @ [*(np.add(cam.eye, up)), 1.0], [0, 1, 0, 1], atol=1e-14)
    attrs = cam.header_attributes()
    assert "fov 35 deg 10x10" in attrs["subtrace:camera"]
    # OpenEXR's worldToCamera is the row-vector form: the transpose
    np.testing.assert_array_equal(np.reshape(attrs["worldToCamera"], (4, 4)), m.T)


@pytest.mark.parametrize("size", [(8, 6), (1280, 720), (3, 11)])
def test_world_to_ndc_maps_pixel_rays_to_pixel_centres(size):
    """A point on the ray through pixel (row, col), at any distance, lands at
    ((col + 0.5) / width, (row + 0.5) / height) in NDC; the target at (0.5, 0.5)."""
    w, h = size
    cam = Camera((1.0, 2.0, 3.0), (-2.0, 0.5, 1.0), (0.0, 1.0, 0.0), 35.0, w, h)
    m = cam.world_to_ndc()
    X, Y, _, W = m @ [*cam.target, 1.0]
    assert (X / W, Y / W) == pytest.approx((0.5, 0.5), abs=1e-12)
    dirs = cam.ray_directions()
    for row, col in [(0, 0), (h - 1, w - 1), (h // 2, 0), (0, w - 1)]:
        for dist in (0.5, 7.0):
            p = np.asarray(cam.eye) + dist * dirs[row, col]
            X, Y, _, W = m @ [*p, 1.0]
            assert (X / W, Y / W) == pytest.approx(((col + 0.5) / w, (row + 0.5) / h),
                                                   abs=1e-12)
    np.testing.assert_array_equal(np.reshape(cam.header_attributes()["worldToNDC"], (4, 4)),
                                  m.T)


def test_camera_is_frozen_and_normalises_types():
    cam = Camera([0, 0, 5], np.array([0, 0, 0]), (0, 1, 0), 40, np.int64(8), 6)
    assert cam.eye == (0.0, 0.0, 5.0) and isinstance(cam.eye[0], float)
    assert isinstance(cam.width, int) and cam.width == 8
    with pytest.raises(AttributeError):
        cam.width = 3
    assert cam == simple(width=8, height=6)


# --------------------------------------------------------------------------------------
# auto camera
# --------------------------------------------------------------------------------------


def corners_in_frustum(cam: Camera, lo, hi) -> bool:
    right, up, forward = cam.basis()
    tan_v = math.tan(math.radians(cam.fov_deg) / 2)
    tan_h = tan_v * cam.width / cam.height
    for corner in np.array(np.meshgrid(*zip(lo, hi))).reshape(3, -1).T:
        v = corner - np.asarray(cam.eye)
        z = v @ forward
        if not (z > 0 and abs(v @ right) < tan_h * z and abs(v @ up) < tan_v * z):
            return False
    return True


@pytest.mark.parametrize(
    "lo, hi, width, height, fov",
    [
        ((-1, -1, -1), (1, 1, 1), 640, 480, 30.0),
        ((-1, -1, -1), (1, 1, 1), 200, 800, 30.0),  # portrait: horizontal fov is smaller
        ((10, 20, 30), (10.5, 29, 31), 320, 240, 45.0),  # thin, tall, off-centre
        ((-5, 0, -5), (5, 0, 5), 100, 100, 10.0),  # flat
        ((1e-3, 1e-3, 1e-3), (2e-3, 2e-3, 2e-3), 64, 64, 90.0),  # tiny
        ((1e6, -1e6, 0), (1e6 + 1, -1e6 + 1, 1), 64, 48, 30.0),  # far from the origin
    ],
)
def test_auto_camera_sees_all_box_corners(lo, hi, width, height, fov):
    cam = auto_camera(lo, hi, width, height, fov)
    assert (cam.width, cam.height, cam.fov_deg) == (width, height, fov)
    assert cam.up == (0.0, 1.0, 0.0)
    np.testing.assert_allclose(cam.target, 0.5 * (np.add(lo, hi)), rtol=1e-15)
    assert corners_in_frustum(cam, lo, hi)
    # not absurdly far: the bounding sphere fills most of the smaller field of view
    radius = 0.5 * np.linalg.norm(np.subtract(hi, lo))
    half = min(math.radians(fov) / 2, math.atan(math.tan(math.radians(fov) / 2) * width / height))
    dist = np.linalg.norm(np.subtract(cam.eye, cam.target))
    assert radius / dist > 0.8 * math.sin(half)


@pytest.mark.parametrize("up", [(0, 0, 1), (0, -1, 0), (1, 1, 0), (0, 2, 0)])
def test_auto_camera_other_up(up):
    lo, hi = (-1, -2, -3), (3, 2, 1)
    cam = auto_camera(lo, hi, 320, 240, 30.0, up=up)
    assert cam.up == tuple(float(c) for c in up)
    assert corners_in_frustum(cam, lo, hi)
    # seen from the same elevation as with +Y up: AUTO_VIEW_DIRECTION's y along up
    view = np.subtract(cam.eye, cam.target)
    view /= np.linalg.norm(view)
    ref = np.array(AUTO_VIEW_DIRECTION) / np.linalg.norm(AUTO_VIEW_DIRECTION)
    assert view @ (np.array(up) / np.linalg.norm(up)) == pytest.approx(ref[1], abs=1e-14)
    if up == (0, 2, 0):
        np.testing.assert_allclose(view, ref, atol=1e-15)


def test_auto_camera_default_fov_and_point_box():
    cam = auto_camera((1, 2, 3), (1, 2, 3), 32, 32)
    assert cam.fov_deg == 30.0
    assert cam.target == (1.0, 2.0, 3.0) and cam.eye != cam.target


@pytest.mark.parametrize(
    "lo, hi",
    [
        ((0, 0, 0), (1, np.inf, 1)),
        ((0, 0, np.nan), (1, 1, 1)),
        ((1, 0, 0), (0, 1, 1)),  # empty
        ((0, 0), (1, 1)),
    ],
)
def test_auto_camera_bad_bounds(lo, hi):
    with pytest.raises(SceneError, match="auto camera"):
        auto_camera(lo, hi, 64, 64)


# --------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------

GOOD = dict(eye=(0, 0, 5), target=(0, 0, 0), up=(0, 1, 0), fov_deg=40, width=64, height=48)


@pytest.mark.parametrize(
    "change, key, words",
    [
        ({"target": (0, 0, 5)}, "target", "coincide"),
        ({"eye": (1e8, 0, 0), "target": (1e8, 0, 0)}, "target", "coincide"),
        # (a distance that overflows is not a coincidence: found by fuzzing, seed 25)
        ({"eye": (1e300, 0, 0), "target": (0, 0, 0)}, "eye", "beyond 1e+100"),
        ({"target": (0, -1e200, 0)}, "target", "beyond 1e+100"),
        ({"up": (0, 0, 3)}, "up", "parallel"),
        ({"up": (0, 0, -1)}, "up", "parallel"),
        ({"up": (0, 0, 0)}, "up", "zero"),
        ({"fov_deg": 0}, "fov_deg", "between 0 and 180"),
        ({"fov_deg": 180}, "fov_deg", "between 0 and 180"),
        ({"fov_deg": -10}, "fov_deg", "between 0 and 180"),
        ({"fov_deg": math.nan}, "fov_deg", "between 0 and 180"),
        ({"fov_deg": "40"}, "fov_deg", "expected a number"),
        ({"width": 0}, "width", "between 1 and 32768"),
        ({"width": -4}, "width", "between 1 and 32768"),
        ({"height": MAX_RESOLUTION + 1}, "height", "between 1 and 32768"),
        ({"height": 48.0}, "height", "whole number"),
        ({"width": True}, "width", "whole number"),
        ({"eye": (0, 0, math.inf)}, "eye", "finite"),
        ({"target": (0, math.nan, 0)}, "target", "finite"),
        ({"eye": (0, 0)}, "eye", "3 numbers"),
        ({"up": "y"}, "up", "3 numbers"),
    ],
)
def test_bad_camera_raises(change, key, words):
    with pytest.raises(SceneError) as info:
        Camera(**{**GOOD, **change})
    assert info.value.key == key
    assert words in str(info.value)


def test_largest_resolution_is_accepted():
    cam = Camera(**{**GOOD, "width": MAX_RESOLUTION, "height": 1})
    assert cam.width == MAX_RESOLUTION


# --------------------------------------------------------------------------------------
# property test
# --------------------------------------------------------------------------------------

coord = st.floats(-100, 100, allow_nan=False)
vec = st.tuples(coord, coord, coord)


@settings(max_examples=60, deadline=None)
@given(
    eye=vec,
    target=vec,
    up=vec,
    fov=st.floats(1.0, 170.0),
    width=st.integers(1, 9),
    height=st.integers(1, 9),
)
def test_random_cameras(eye, target, up, fov, width, height):
    view = np.subtract(target, eye)
    assume(np.linalg.norm(view) > 1e-3 and np.linalg.norm(up) > 1e-3)
    assume(angle(view, up) > 1e-3 and angle(view, np.negative(up)) > 1e-3)
    cam = Camera(eye, target, up, fov, width, height)
    d = cam.ray_directions()
    # unit length: one correctly rounded division per component, a few ulps at most
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, rtol=0, atol=4e-16)
    # the ray through the image centre is parallel to target - eye
    centre = ray_direction(camera_frame(cam), (height - 1) / 2, (width - 1) / 2)
    assert angle(centre, view) < 1e-12
    if width % 2 and height % 2:
        assert angle(d[height // 2, width // 2], view) < 1e-12
    # the frame is orthonormal and right-handed (x right, y up, z backwards)
    right, true_up, forward = cam.basis()
    np.testing.assert_allclose(np.cross(right, true_up), -forward, atol=1e-14)


def test_parallel_up_suggests_an_up_that_works():
    """Looking straight down with the default up: the message's suggestion is not [0, 1, 0]
    (parallel too) but a vector with which the same view is accepted."""
    import re

    from subtrace.camera import check_view
    from subtrace.errors import SceneError

    eye, target = (0.0, 5.0, 0.0), (0.0, 0.0, 0.0)
    with pytest.raises(SceneError) as err:
        check_view(eye, target, (0.0, 1.0, 0.0))
    suggested = re.search(r"e\.g\. \[([^\]]*)\]", str(err.value)).group(1)
    up = tuple(float(x) for x in suggested.split(","))
    assert up != (0.0, 1.0, 0.0)
    check_view(eye, target, up)


@settings(max_examples=200, deadline=None)
@given(st.tuples(*[st.floats(-1e3, 1e3)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3))
def test_across_view_is_never_parallel(view):
    from subtrace.camera import across_view, check_view

    d = np.asarray(view) / np.linalg.norm(view)
    check_view((0.0, 0.0, 0.0), tuple(d), across_view(d))


def test_auto_camera_frames_points_within_the_margin_and_tightly():
    """With surface points the automatic camera fits them, not the box's empty corners:
    every point projects within 1 / AUTO_MARGIN of the half-image, and one reaches it."""
    from subtrace.camera import AUTO_MARGIN

    rng = np.random.default_rng(3)
    pts = rng.normal(size=(300, 3)) * [0.5, 1.0, 0.3] + [2.0, 0.0, 1.0]
    cam = auto_camera(pts.min(axis=0), pts.max(axis=0), 1280, 720, 30.0, points=pts)
    right, up, forward = cam.basis()
    rel = pts - np.asarray(cam.eye)
    depth = rel @ forward
    tan_v = math.tan(math.radians(15.0))
    fill = np.maximum(np.abs(rel @ right / depth) / (tan_v * 1280 / 720),
                      np.abs(rel @ up / depth) / tan_v)
    assert fill.max() <= 1.0 / AUTO_MARGIN + 1e-12
    assert fill.max() >= 1.0 / AUTO_MARGIN - 1e-9
    # the box of the points alone would leave them smaller
    boxed = auto_camera(pts.min(axis=0), pts.max(axis=0), 1280, 720, 30.0)
    assert np.linalg.norm(np.subtract(boxed.eye, boxed.target)) > np.linalg.norm(
        np.subtract(cam.eye, cam.target))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-3, 3),
                          st.floats(0.01, 4), st.floats(0.01, 4), st.floats(0.01, 4)),
                min_size=1, max_size=4),
       st.floats(0.05, 1.0))
def test_auto_camera_keeps_the_eye_outside_the_boxes(boxes, shrink):
    """With boxes to keep out of (cages' control points, whose shells hold their patches),
    the eye lies outside each, grown by AUTO_BOX_MARGIN of its diagonal, and still looks
    at the framed points' centre along AUTO_VIEW_DIRECTION: framing a limit surface far
    smaller than its cage (a Loop tetrahedron) put the eye among the shells."""
    from subtrace.camera import AUTO_BOX_MARGIN

    outside = [(np.array(b[:3]), np.array(b[:3]) + np.array(b[3:])) for b in boxes]
    lo, hi = outside[0]
    mid = 0.5 * (lo + hi)
    pts = mid + shrink * 0.5 * (np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                                          for sz in (-1, 1)]) * (hi - lo))
    free = auto_camera(pts.min(0), pts.max(0), 64, 48, points=pts)
    cam = auto_camera(pts.min(0), pts.max(0), 64, 48, points=pts, outside=outside)
    eye = np.array(cam.eye)
    for blo, bhi in outside:
        pad = AUTO_BOX_MARGIN * np.linalg.norm(bhi - blo)
        assert np.any(eye < blo - pad) or np.any(eye > bhi + pad)
    assert cam.target == free.target
    view = eye - np.array(cam.target)
    assert angle(view, AUTO_VIEW_DIRECTION) < 1e-9
    assert np.linalg.norm(view) >= np.linalg.norm(np.array(free.eye) - free.target) - 1e-12
