# subtrace.camera: the pinhole camera and its primary rays.
#
# Owns the camera model only (no scene parsing, no tracing). Conventions:
#   forward = normalize(target - eye); right = normalize(forward x up);
#   true_up = right x forward. Camera space is right-handed with x = right, y = true_up and
#   z = -forward (the OpenGL / OpenEXR `worldToCamera` convention: the camera looks down -z).
#   Image +x (increasing column) is `right`, image row 0 is the top (towards `true_up`).
#   The image plane lies at unit distance along `forward`; its height is 2 tan(fov/2) with
#   `fov` the vertical field of view; pixels are square, of side s = 2 tan(fov/2) / height.
#   The ray of pixel (row, col) goes from `eye` through the pixel centre:
#     d(row, col) = p00 + col * dx + row * dy,  then normalised,
#   with p00 the centre of pixel (0, 0), dx = s * right and dy = -s * true_up.
# Kernels take the (4,3) float64 array of `camera_frame` ([eye, dx, dy, p00]) and call the
# jitted `ray_direction(frame, row, col)`; row and col may be fractional (pixel corners are
# at row +- 0.5, col +- 0.5). `Camera.ray_directions` is the same arithmetic in numpy, in the
# same order, so both give the same bits.
# A window of the image (`CameraWindow`: a tile, ``render --crop``) is traced as an image of
# its own size whose frame has a fifth row, the window's offset (col0, row0, 0) in its
# image: `geometry.prims.ray_setup` adds it to the window's (row, col) before the arithmetic
# above, so a window pixel's ray is its image pixel's, bit for bit (an integer offset added
# to an integer is exact; p00 moved by the offset would not be).

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from subtrace.runtime.jit import nb

njit = nb.njit

from subtrace.errors import SceneError, show_value

MAX_RESOLUTION = 32768  # pixels per side, inclusive
# auto_camera: from the box centre towards the eye: a three-quarter view from the front
# (+z, the usual front of an OBJ model), about 22 degrees above the horizon
AUTO_VIEW_DIRECTION = (1.0, 0.62, 1.3)
AUTO_MARGIN = 1.15  # auto_camera: what it frames fills at most 1 / 1.15 of the half-image
# auto_camera: the eye stays this share of a box's diagonal outside each box it is kept
# out of (a cage's control points: the shells of its patches lie within, and an eye among
# them makes the patches near it refine without end)
AUTO_BOX_MARGIN = 0.1
# up within this angle (radians) of the view direction is "parallel": the frame is undefined
_MIN_UP_ANGLE = 1e-6


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: eye, target, up (world space), vertical field of view, resolution.

    ``eye``, ``target``, ``up``: 3 finite numbers each (stored as float tuples); ``fov_deg``:
    vertical field of view in degrees, in (0, 180); ``width``, ``height``: pixels, 1..32768.
    Invalid values raise :class:`SceneError` whose ``key`` is the field name.
    """

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float
    width: int
    height: int

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "eye", check_vector(self.eye, "eye"))
        set_(self, "target", check_vector(self.target, "target"))
        set_(self, "up", check_vector(self.up, "up"))
        set_(self, "fov_deg", check_fov(self.fov_deg, "fov_deg"))
        set_(self, "width", check_resolution(self.width, "width"))
        set_(self, "height", check_resolution(self.height, "height"))
        check_view(self.eye, self.target, self.up)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(right, up, forward): orthonormal (3,) float64 world-space vectors.

        ``up`` is the true up (the given up made orthogonal to the view direction);
        right x up = -forward.
        """
        return _basis(self.eye, self.target, self.up)

    def pixel_size(self) -> float:
        """Side of one pixel on the image plane at unit distance: 2 tan(fov/2) / height."""
        return 2.0 * math.tan(math.radians(self.fov_deg) / 2.0) / self.height

    def pixel_angle(self) -> float:
        """Angle (radians) subtended by one pixel at the image centre: 2 atan(tan(fov/2)/H).

        The unit of the angular tolerance: ``--tolerance 1`` means this angle.
        """
        return 2.0 * math.atan(math.tan(math.radians(self.fov_deg) / 2.0) / self.height)

    def frame(self) -> np.ndarray:
        """Same as :func:`camera_frame`."""
        return camera_frame(self)

    def ray_directions(self) -> np.ndarray:
        """(height, width, 3) float64 unit directions through the pixel centres, row 0 at top."""
        frame = camera_frame(self)
        rows = np.arange(self.height, dtype=np.float64)[:, None]
        cols = np.arange(self.width, dtype=np.float64)[None, :]
        comps = []
        for k in range(3):  # same operation order as ray_direction
            comps.append(frame[3, k] + cols * frame[1, k] + rows * frame[2, k])
        x, y, z = comps
        n = np.sqrt(x * x + y * y + z * z)
        return np.ascontiguousarray(np.stack((x / n, y / n, z / n), axis=-1))

    def world_to_camera(self) -> np.ndarray:
        """(4,4) float64 matrix, column-vector convention: p_cam = M @ [p_world, 1].

        Camera space as OpenEXR's ``worldToCamera`` defines it: origin at the eye, x right,
        y up, z along the viewing direction (left-handed; points in front have z > 0).
        """
        right, up, forward = self.basis()
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = right, up, forward
        m[:3, 3] = -(m[:3, :3] @ np.asarray(self.eye))
        return m

    def world_to_ndc(self) -> np.ndarray:
        """(4,4) float64 matrix, column-vector convention: [X, Y, Z, W] = M @ [p_world, 1],
        and (X / W, Y / W) the point's normalised device coordinates as OpenEXR's
        ``worldToNDC`` defines them: (0, 0) the image's upper left corner, (1, 1) its lower
        right (pixel (row, col) is centred at ((col + 0.5) / width, (row + 0.5) / height));
        Z / W is 1 (the image plane at unit distance)."""
        s = self.pixel_size()
        proj = np.array([
            [1.0 / (s * self.width), 0.0, 0.5, 0.0],
            [0.0, -1.0 / (s * self.height), 0.5, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ])
        return proj @ self.world_to_camera()

    def header_attributes(self) -> dict:
        """EXR header attributes describing the camera (see :func:`subtrace.io.exr.write_exr`).

        ``subtrace:camera`` is a readable summary; ``worldToCamera`` and ``worldToNDC`` are
        OpenEXR's standard attributes (Imath's row-vector convention: the transposes of
        :meth:`world_to_camera` and :meth:`world_to_ndc`).
        """
        summary = (
            f"eye {_fmt(self.eye)} target {_fmt(self.target)} up {_fmt(self.up)} "
            f"fov {self.fov_deg:.9g} deg {self.width}x{self.height}"
        )
        return {
            "subtrace:camera": summary,
            "subtrace:camera_fov_deg": float(self.fov_deg),
            "worldToCamera": tuple(float(v) for v in self.world_to_camera().T.ravel()),
            "worldToNDC": tuple(float(v) for v in self.world_to_ndc().T.ravel()),
        }


def camera_frame(camera: Camera) -> np.ndarray:
    """(4,3) float64 C-contiguous [eye, dx, dy, p00] for kernels (see the module comment).

    dx, dy: image-plane step (unit distance from the eye) per column / per row; p00: the
    point through the centre of pixel (0, 0), relative to the eye.
    """
    right, up, forward = camera.basis()
    s = camera.pixel_size()
    frame = np.empty((4, 3), dtype=np.float64)
    frame[0] = camera.eye
    frame[1] = s * right
    frame[2] = -s * up
    frame[3] = (
        forward + (0.5 - 0.5 * camera.width) * frame[1] + (0.5 - 0.5 * camera.height) * frame[2]
    )
    return frame


@dataclass(frozen=True)
class CameraWindow:
    """Pixels [x0, x0 + width) x [y0, y0 + height) of ``camera``'s image, traced as an image
    of their own (``render --crop``). ``frame()`` is the camera's frame with a fifth row,
    the offset (x0, y0, 0); any other attribute is the camera's (eye, up, pixel_angle ...)."""

    camera: Camera
    x0: int
    y0: int
    width: int
    height: int

    def frame(self) -> np.ndarray:
        """(5,3) float64: :func:`camera_frame` of the camera, then (x0, y0, 0)."""
        frame = np.zeros((5, 3), dtype=np.float64)
        frame[:4] = camera_frame(self.camera)
        frame[4, 0], frame[4, 1] = self.x0, self.y0
        return frame

    def __getattr__(self, name):
        return getattr(self.camera, name)


def whole_image(view) -> Camera:
    """The camera of ``view``: the Camera itself, or a :class:`CameraWindow`'s."""
    return view.camera if isinstance(view, CameraWindow) else view


def window_offset(frame) -> tuple[int, int]:
    """(col0, row0): the offset of a window's frame in its image ((0, 0): a whole image)."""
    if len(frame) > 4:
        return int(frame[4, 0]), int(frame[4, 1])
    return 0, 0


@njit(cache=True, nogil=True)
def ray_direction(frame, row, col):
    """Unit direction (x, y, z) of the ray through image point (row, col) of `frame`.

    frame: (4,3) float64 from :func:`camera_frame`; row, col: pixel coordinates (integers
    for pixel centres; fractional values allowed). Returns a tuple of three floats.
    """
    # image-plane point at unit distance along forward, relative to the eye
    x = frame[3, 0] + col * frame[1, 0] + row * frame[2, 0]
    y = frame[3, 1] + col * frame[1, 1] + row * frame[2, 1]
    z = frame[3, 2] + col * frame[1, 2] + row * frame[2, 2]
    # normalise
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


def auto_camera(
    bounds_min, bounds_max, width: int, height: int, fov_deg: float = 30.0, up=(0.0, 1.0, 0.0),
    points=None, outside=(),
) -> Camera:
    """A camera that frames the axis-aligned box [bounds_min, bounds_max].

    Looks at the box centre from the direction AUTO_VIEW_DIRECTION (normalised, given for
    +Y up; for another ``up`` it is rotated by the smallest rotation taking +Y to ``up``), at
    the nearest distance where all eight corners of the box project inside the image with
    a margin (AUTO_MARGIN: each corner within 1 / AUTO_MARGIN of the half-width and
    half-height from the centre). A box of zero size is taken as a unit cube. With
    ``points`` (n,3) (points of the surface, e.g. limit points), those are framed instead
    of the corners, the target moved so that their extent across the view is centred:
    a box's empty corners would leave the object small in a three-quarter view. The eye
    then moves back along its direction, where it must, until it lies outside each box
    (lo, hi) of ``outside`` by ``AUTO_BOX_MARGIN`` of the box's diagonal.
    """
    lo = np.asarray(bounds_min, dtype=np.float64).reshape(-1)
    hi = np.asarray(bounds_max, dtype=np.float64).reshape(-1)
    if lo.shape != (3,) or hi.shape != (3,):
        raise SceneError("auto camera: bounds must be two 3-vectors")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise SceneError("auto camera: the scene bounds are not finite")
    if np.any(lo > hi):
        raise SceneError("auto camera: empty scene bounds (min > max)")
    fov_deg = check_fov(fov_deg, "fov_deg")
    width = check_resolution(width, "width")
    height = check_resolution(height, "height")
    up = check_vector(up, "up")
    centre = 0.5 * (lo + hi)
    half_size = 0.5 * (hi - lo)
    if not float(np.abs(half_size).max()) > 1e-12 * max(1.0, float(np.abs(centre).max())):
        half_size = np.full(3, 0.5)
    tan_v = math.tan(math.radians(fov_deg) / 2.0)
    tan_h = tan_v * width / height
    direction = _y_up_to(up) @ np.asarray(AUTO_VIEW_DIRECTION, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    right, true_up, _ = _basis(centre + direction, centre, up)
    # each corner r (relative to the centre) at depth distance - r.direction must see its
    # offsets along right and up within the margin's share of the half-fields
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corners = signs * half_size
    if points is not None and len(points):
        corners = np.asarray(points, np.float64).reshape(-1, 3) - centre
        if np.all(np.isfinite(corners)):
            x, y = corners @ right, corners @ true_up
            shift = 0.5 * (x.min() + x.max()) * right + 0.5 * (y.min() + y.max()) * true_up
            centre = centre + shift
            corners = corners - shift
    need = corners @ direction + AUTO_MARGIN * np.maximum(
        np.abs(corners @ right) / tan_h, np.abs(corners @ true_up) / tan_v)
    distance = _outside_boxes(centre, direction, float(need.max()), outside)
    eye = centre + distance * direction
    return Camera(
        eye=tuple(eye.tolist()),
        target=tuple(centre.tolist()),
        up=up,
        fov_deg=fov_deg,
        width=width,
        height=height,
    )


def _outside_boxes(centre, direction, distance: float, boxes) -> float:
    """The least distance from ``distance`` on at which ``centre + distance * direction``
    lies outside every box (lo, hi) of ``boxes``, each grown by ``AUTO_BOX_MARGIN`` of its
    diagonal."""
    grown = []
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        pad = AUTO_BOX_MARGIN * float(np.linalg.norm(hi - lo))
        grown.append((lo - pad, hi + pad))
    for _ in range(len(grown) + 1):  # (each pass leaves one box at least behind)
        moved = False
        for lo, hi in grown:
            eye = centre + distance * direction
            if np.all(eye >= lo) and np.all(eye <= hi):
                # where the ray from the centre leaves this box
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = np.where(direction > 0, (hi - centre) / direction,
                                 np.where(direction < 0, (lo - centre) / direction, np.inf))
                distance = float(t.min()) * (1.0 + 1e-9)  # (just beyond, rounding aside)
                moved = True
        if not moved:
            break
    return distance


# --------------------------------------------------------------------------------------
# validation (shared with subtrace.io.scene; `key` names the field in the error)
# --------------------------------------------------------------------------------------


def _is_number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def check_vector(value, key: str) -> tuple[float, float, float]:
    """3 finite numbers as a float tuple, else SceneError(key=key)."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise SceneError(f"expected 3 numbers [x, y, z], got {value!r}", key=key)
    items = list(value)
    if len(items) != 3 or not all(_is_number(v) for v in items):
        raise SceneError(f"expected 3 numbers [x, y, z], got {show_value(value)}", key=key)
    out = tuple(float(v) for v in items)
    if not all(math.isfinite(v) for v in out):
        raise SceneError(f"expected finite numbers, got {show_value(value)}", key=key)
    return out


def check_fov(value, key: str) -> float:
    """A vertical field of view in degrees, strictly between 0 and 180."""
    if not _is_number(value):
        raise SceneError(f"expected a number of degrees, got {show_value(value)}", key=key)
    value = float(value)
    if not (0.0 < value < 180.0):
        raise SceneError(
            f"field of view must be between 0 and 180 degrees (exclusive), got {value:g}; "
            "typical values are 20 to 60",
            key=key,
        )
    return value


def check_resolution(value, key: str) -> int:
    """An image size in pixels, 1..MAX_RESOLUTION."""
    if not _is_number(value) or isinstance(value, (float, np.floating)):
        raise SceneError(f"expected a whole number of pixels, got {show_value(value)}", key=key)
    if not (1 <= value <= MAX_RESOLUTION):
        raise SceneError(
            f"must be between 1 and {MAX_RESOLUTION} pixels, got {show_value(value)}", key=key
        )
    return int(value)


# the farthest an eye or target may lie from the origin: squared distances (ray setup,
# shells' distances) stay finite in float64 well past it
MAX_VIEW_COORD = 1e100


def check_view(eye, target, up) -> None:
    """eye != target and up not parallel to the view direction; SceneError otherwise.

    The error's key is ``eye`` or ``target`` for one too far from the origin
    (``MAX_VIEW_COORD``), ``target`` for eye == target and ``up`` for a parallel up.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.subtract(target, eye, dtype=np.float64)
        dist = float(np.linalg.norm(d))
        far_eye = float(np.linalg.norm(eye))
        scale = max(far_eye, float(np.linalg.norm(target)))
    if not (math.isfinite(dist) and scale <= MAX_VIEW_COORD):
        which, where = ("eye", eye) if not far_eye <= MAX_VIEW_COORD else ("target", target)
        raise SceneError(
            f"{which} {_fmt(where)} lies beyond {MAX_VIEW_COORD:g} from the origin, where the "
            "camera's distances overflow; scale the scene down or move it nearer the origin",
            key=which,
        )
    if not dist > 4.0 * np.finfo(np.float64).eps * scale or dist == 0.0:
        raise SceneError(
            f"eye {_fmt(eye)} and target {_fmt(target)} coincide; the camera needs a view "
            "direction: move the eye or the target",
            key="target",
        )
    u = np.asarray(up, dtype=np.float64)
    un = float(np.linalg.norm(u))
    if un == 0.0:
        raise SceneError("up vector is zero; use e.g. [0, 1, 0]", key="up")
    sin_angle = float(np.linalg.norm(np.cross(d / dist, u / un)))
    if not sin_angle > math.sin(_MIN_UP_ANGLE):
        raise SceneError(
            f"up {_fmt(up)} is parallel to the view direction {_fmt(tuple(d / dist))} "
            f"(target - eye); choose an up vector that is not along the view, e.g. "
            f"{_fmt(across_view(d / dist))}",
            key="up",
        )


def across_view(view) -> tuple:
    """The coordinate axis most nearly perpendicular to the unit direction ``view`` (at least
    54.7 degrees from it): an up vector that works for that view."""
    k = int(np.argmin(np.abs(view)))
    return tuple(1.0 if i == k else 0.0 for i in range(3))


def _y_up_to(up) -> np.ndarray:
    """(3,3) rotation taking +Y to the unit vector along `up` (Rodrigues' formula)."""
    norm = math.sqrt(sum(c * c for c in up))
    if norm == 0.0:
        raise SceneError("up vector is zero; use e.g. [0, 1, 0]", key="up")
    b = np.asarray(up, dtype=np.float64) / norm
    c = b[1]  # cos of the angle between +Y and b
    if c < -1.0 + 1e-12:  # -Y: half a turn about X
        return np.diag([1.0, -1.0, -1.0])
    v = np.array([b[2], 0.0, -b[0]])  # +Y x b
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _basis(eye, target, up):
    forward = np.subtract(target, eye, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    true_up /= np.linalg.norm(true_up)
    return right, true_up, forward


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(x):.9g}" for x in v) + "]"
