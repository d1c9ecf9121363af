"""Small kernels on one square of a patch and its 4x4 control grid, shared by the fixed
maps of the isolation (``patches/crease.py``, ``patches/gridmaps.py``): the eye as the
kernels take it, the distance of a box from it, the levels a bound needs, a grid's Bezier
net, a net's box and derivative bound, a grid's one-ring shell. Each makes what its NumPy
counterpart makes (``shells.sight_distance``, ``grids.levels_needed``,
``basis.to_bezier``, ``basis.net_summary``, ``shells.one_ring_shells``) with the same sums
in the same order, so the maps' depths equal the topological path's.
"""

from __future__ import annotations

import math

import numpy as np

from subtrace.patches.shells import Sight
from subtrace.runtime.jit import leaf_njit
from subtrace.runtime.threads import run_chunks, thread_count


def in_chunks(call, m, per_chunk, square_rows):
    """``call(a, b)`` (a map kernel's results for its squares ``a .. b - 1``) for all ``m``
    squares: in one call, or in chunks of ``per_chunk`` squares on the thread pool, the
    chunks' results one after another and the results at ``square_rows`` (square numbers
    within the chunk) offset by the chunk's first. A square's own results come in the order
    of one call, and every caller orders them by square first, so the result does not
    depend on the chunks or the threads."""
    if m <= per_chunk or thread_count() == 1:
        return call(0, m)
    parts = {}

    def work(t, a, b):
        parts[a] = call(a, b)

    run_chunks(work, m, per_chunk)
    starts = sorted(parts)
    got = [parts[a] for a in starts]
    out = [np.concatenate([g[0] for g in got])]
    for k in range(1, len(got[0])):
        out.append(np.concatenate([g[k] + a if k in square_rows else g[k]
                                   for a, g in zip(starts, got)]))
    return tuple(out)


def sight(eye):
    """The eye as the kernel takes it: ``(eye (3,), near, seen_min (3,), seen_max (3,),
    cone)``, ``cone`` whether ``eye`` is a :class:`~subtrace.patches.shells.Sight` (else the
    other three are unused); ``eye`` None: zeros (the pieces then take their patch's
    depth)."""
    if eye is None:
        z = np.zeros(3)
        return z, 0.0, z, z, False
    if isinstance(eye, Sight):
        return (np.asarray(eye.eye, np.float64), float(eye.near),
                np.asarray(eye.seen_min, np.float64), np.asarray(eye.seen_max, np.float64),
                True)
    z = np.zeros(3)
    return np.asarray(eye, np.float64), 0.0, z, z, False


@leaf_njit
def nan_max(a, b):
    """``np.maximum(a, b)`` of two floats (a NaN wins)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@leaf_njit
def nan_min(a, b):
    """``np.minimum(a, b)`` of two floats (a NaN wins)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a <= b else b


@leaf_njit
def distance(lo, hi, r, eye, near, seen_min, seen_max, cone):
    """``shells.sight_distance`` of box row ``r`` of ``lo``, ``hi``, in its sums' order."""
    d = 0.0
    for k in range(3):
        q = nan_max(nan_max(lo[r, k] - eye[k], 0.0), eye[k] - hi[r, k])
        d += q * q
    d = math.sqrt(d)
    if not cone:
        return d
    g = 0.0
    for k in range(3):
        q = nan_max(nan_max(lo[r, k] - seen_max[k], seen_min[k] - hi[r, k]), 0.0)
        g += q * q
    return nan_max(d, near + math.sqrt(g))


@leaf_njit
def needed(bound, dist, tol_rad):
    """``grids.levels_needed`` of one bound (a float: 1e9 where it is not finite)."""
    allowed = tol_rad * dist
    if bound <= allowed:
        return 0.0
    n = math.ceil(math.log2(bound / allowed) - 1e-9)
    return n if math.isfinite(n) else 1e9


@leaf_njit
def bezier(cv, M, tmp, out):
    """The Bezier net ``out`` (4,4,3) of the B-spline grid ``cv`` (4,4,3), ``M`` =
    ``basis.TO_BEZIER``: ``basis.to_bezier``'s sums in its order (so the same bits), with
    its scratch ``tmp`` (4,4,3) given (``to_bezier`` allocates its own per call: half the
    time of the maps' kernel)."""
    for a in range(4):
        for j in range(4):
            for k in range(3):
                tmp[a, j, k] = (M[a, 0] * cv[0, j, k] + M[a, 1] * cv[1, j, k]
                                + M[a, 2] * cv[2, j, k] + M[a, 3] * cv[3, j, k])
    for a in range(4):
        for b in range(4):
            for k in range(3):
                out[a, b, k] = (M[b, 0] * tmp[a, 0, k] + M[b, 1] * tmp[a, 1, k]
                                + M[b, 2] * tmp[a, 2, k] + M[b, 3] * tmp[a, 3, k])


@leaf_njit
def net_bounds(bez, s, lo, hi, bound):
    """Row ``s`` of the box ``lo``, ``hi`` and derivative bound ``bound`` of the net
    ``bez`` (4,4,3), as ``basis.net_summary`` makes them."""
    for k in range(3):
        lo[s, k] = np.inf
        hi[s, k] = -np.inf
    best = 0.0
    for a in range(4):
        for b in range(4):
            for k in range(3):
                lo[s, k] = min(lo[s, k], bez[a, b, k])
                hi[s, k] = max(hi[s, k], bez[a, b, k])
            if a < 3:
                dx = bez[a + 1, b, 0] - bez[a, b, 0]
                dy = bez[a + 1, b, 1] - bez[a, b, 1]
                dz = bez[a + 1, b, 2] - bez[a, b, 2]
                best = max(best, dx * dx + dy * dy + dz * dz)
            if b < 3:
                dx = bez[a, b + 1, 0] - bez[a, b, 0]
                dy = bez[a, b + 1, 1] - bez[a, b, 1]
                dz = bez[a, b + 1, 2] - bez[a, b, 2]
                best = max(best, dx * dx + dy * dy + dz * dz)
    # (the root of the longest square: a correctly rounded root never decreases, so it is
    # the longest of the roots, bit for bit, at one root a net instead of 24)
    bound[s] = 3.0 * math.sqrt(best)


@leaf_njit
def square_shell(grids, m, lo, hi, bound):
    """Box and length bound of the one-ring of square ``m`` whose one-ring is its grid
    ``grids[m]`` (4,4,3), as ``shells.one_ring_shells`` makes them: the grid's box, and
    ``(4 own + 5 most) / 9`` of the longest of its own sides and of every edge of the
    grid."""
    for k in range(3):
        lo[m, k], hi[m, k] = np.inf, -np.inf
    own = 0.0
    most = 0.0
    for a in range(4):
        for b in range(4):
            for k in range(3):
                lo[m, k] = min(lo[m, k], grids[m, a, b, k])
                hi[m, k] = max(hi[m, k], grids[m, a, b, k])
            for da, db in ((1, 0), (0, 1)):
                if a + da > 3 or b + db > 3:
                    continue
                d = 0.0
                for k in range(3):
                    x = grids[m, a + da, b + db, k] - grids[m, a, b, k]
                    d += x * x
                most = max(most, d)
                # the square's own sides: between its corners, points 1 and 2
                if 1 <= a <= 2 and 1 <= b <= 2 and a + da <= 2 and b + db <= 2:
                    own = max(own, d)
    # (roots of the longest squares: the longest roots, as in net_bounds)
    bound[m] = (4.0 * math.sqrt(own) + 5.0 * math.sqrt(most)) / 9.0
