"""Ray primitives shared by the kernels: a ray's working hit record, the watertight ray /
triangle test, ray set-up for a pixel, Woop's shear constants, and a sorted push for
near-first descents. (The slab test is the BVH's, :mod:`subtrace.accel.bvh`.)"""

from __future__ import annotations

import math

import numpy as np

from subtrace.runtime.jit import leaf_njit, llvm_inline_njit

# a ray's working hit record while it is traced (float64 (HIT_FIELDS,) in the thread's
# scratch), stored per ray at the end as :class:`subtrace.trace.pools.Hits`' fields t, prim,
# leaf, item, a, b
H_T, H_SLOT, H_LEAF, H_TRI, H_B1, H_B2 = range(6)
HIT_FIELDS = 6

# a thread's memo of split nets (``geometry/bezier.py`` says what it holds): the rows of its
# counts (nodes, nets and cells in use; a flag set when a store ran out; then, over every
# chunk of rays the memo served, the nodes it made and the most rows of each store it held
# at once), and the state of a node not yet evaluated
M_NODES, M_NETS, M_CELLS, M_FULL, M_MADE, M_PEAK_NODES, M_PEAK_NETS, M_PEAK_CELLS = range(8)
M_COUNTS = 8
NOT_YET = -1


@leaf_njit(python=True)  # (also from Python: pools.Memos.finish)
def memo_restart(root, cnt):
    """Empty a memo (its item ``root`` s and counts ``cnt``) for the next chunk of rays,
    folding what it held into the totals and peaks of ``cnt``. A memo serves one chunk of
    neighbouring rays (``trace/kernels.py``): what a chunk's rays split is what they share,
    and a chunk's work (and the micro-triangles it counts) is then the same whichever thread
    takes it."""
    cnt[M_MADE] += cnt[M_NODES]
    cnt[M_PEAK_NODES] = max(cnt[M_PEAK_NODES], cnt[M_NODES])
    cnt[M_PEAK_NETS] = max(cnt[M_PEAK_NETS], cnt[M_NETS])
    cnt[M_PEAK_CELLS] = max(cnt[M_PEAK_CELLS], cnt[M_CELLS])
    cnt[M_NODES] = 0
    cnt[M_NETS] = 0
    cnt[M_CELLS] = 0
    root[:] = NOT_YET


@leaf_njit
def new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2, row):
    """A new leaf node of a memo (``geometry/bezier.py``): its box and data row; returns it."""
    m = cnt[M_NODES]
    cnt[M_NODES] = m + 1
    child[m] = -1
    box[m, 0], box[m, 1], box[m, 2] = lo0, lo1, lo2
    box[m, 3], box[m, 4], box[m, 5] = hi0, hi1, hi2
    data[m] = row
    return m


@leaf_njit
def push_sorted(ent_t, ent_i, n, te, item):
    """Insert ``item`` with entry distance ``te`` into the first ``n`` entries of
    (ent_t, ent_i), kept in descending distance (so pushing them in order puts the nearest
    on top of a stack); returns the new count."""
    m = n
    while m > 0 and ent_t[m - 1] < te:
        ent_t[m] = ent_t[m - 1]
        ent_i[m] = ent_i[m - 1]
        m -= 1
    ent_t[m] = te
    ent_i[m] = item
    return n + 1


@llvm_inline_njit
def ray_triangle(ox, oy, oz, kx, ky, kz, sx, sy, sz, a, b, c, verts, tmax, slack):
    """Watertight ray / triangle test (Woop, Benthin and Wald 2013) on vertices ``a, b, c``
    of ``verts``; ``ox, oy, oz`` is the ray origin's (kx, ky, kz) components. Returns (t, b_a, b_b, b_c) with t = inf on a miss. Edge functions of a
    shared edge are computed identically from both triangles, so no ray slips between them;
    ``slack`` admits edge functions down to -slack times their sum (see config.TRI_SLACK)."""
    ax = verts[a, kx] - ox
    ay = verts[a, ky] - oy
    az = verts[a, kz] - oz
    bx = verts[b, kx] - ox
    by = verts[b, ky] - oy
    bz = verts[b, kz] - oz
    cx = verts[c, kx] - ox
    cy = verts[c, ky] - oy
    cz = verts[c, kz] - oz
    ax, ay = ax - sx * az, ay - sy * az
    bx, by = bx - sx * bz, by - sy * bz
    cx, cy = cx - sx * cz, cy - sy * cz
    u = cx * by - cy * bx
    v = ax * cy - ay * cx
    w = bx * ay - by * ax
    eps = slack * (abs(u) + abs(v) + abs(w))
    if (u < -eps or v < -eps or w < -eps) and (u > eps or v > eps or w > eps):
        return np.inf, 0.0, 0.0, 0.0
    det = u + v + w
    if det == 0.0:
        return np.inf, 0.0, 0.0, 0.0
    tt = (u * az + v * bz + w * cz) * sz
    t = tt / det
    if not (t > 0.0 and t < tmax):
        return np.inf, 0.0, 0.0, 0.0
    return t, u / det, v / det, w / det


@leaf_njit
def ray_setup(frame, row, col):
    """Unit direction of the ray through the centre of pixel (row, col); a window's frame
    (a fifth row: ``camera.CameraWindow``) first adds its offset in the image."""
    if frame.shape[0] > 4:
        col = col + frame[4, 0]
        row = row + frame[4, 1]
    else:
        col = col + 0.0
        row = row + 0.0
    dx = frame[3, 0] + col * frame[1, 0] + row * frame[2, 0]
    dy = frame[3, 1] + col * frame[1, 1] + row * frame[2, 1]
    dz = frame[3, 2] + col * frame[1, 2] + row * frame[2, 2]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx * inv, dy * inv, dz * inv


@leaf_njit
def shear(dx, dy, dz):
    """Woop's permutation and shear constants of a ray direction."""
    ax, ay, az = abs(dx), abs(dy), abs(dz)
    kz = 0
    if ay > ax and ay >= az:
        kz = 1
    elif az > ax and az > ay:
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    d = (dx, dy, dz)
    dkz = d[kz]
    if dkz < 0.0:
        kx, ky = ky, kx
    return kx, ky, kz, d[kx] / dkz, d[ky] / dkz, 1.0 / dkz


@llvm_inline_njit
def unit_or_cross(nx, ny, nz, pts, a0, a1, b0, b1):
    """The unit of (nx, ny, nz), a blend of a cell's corner normals; where it vanishes (a
    corner's normal undefined), the unit of the cell's own normal ``(pts[a1] - pts[a0]) x
    (pts[b1] - pts[b0])`` (``pts`` (k,3) its corners); (0, 0, 0) where both vanish."""
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (ln > 0.0):
        ax, ay, az = pts[a1, 0] - pts[a0, 0], pts[a1, 1] - pts[a0, 1], pts[a1, 2] - pts[a0, 2]
        bx, by, bz = pts[b1, 0] - pts[b0, 0], pts[b1, 1] - pts[b0, 1], pts[b1, 2] - pts[b0, 2]
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln > 0.0:
        return nx / ln, ny / ln, nz / ln
    return 0.0, 0.0, 0.0
