"""Micro-triangle counts that do not depend on how rays were shared among threads.

Each thread keeps its own memo of the nets its rays split and the cells they evaluated
(``trace/bezier.py``), and the trace kernels count a cell when the first ray *of its thread*
evaluates it. Which thread traces which band of rows depends on timing (a thread that is
done takes chunks from the others), so the sum over threads varied between identical runs
of one scene (3,277,557 / 3,277,561 / 3,280,477 micro-triangles) and with the thread count.

The cells a ray descends to do not depend on the memos (a memo changes where a net comes
from, never which boxes a ray enters or its hit), so the *union* of the threads' memo trees
does not depend on the threads either. :func:`distinct_cells` walks the trees of a set of
memos together and counts each cell once: the render's count is the per-ray sum, less what
each thread's memo holds, plus what their union holds. Cells evaluated on the spot because a
memo was full are counted per ray and stay as they were (``subtrace:memo_full`` says so).
"""

from __future__ import annotations

import numpy as np

from subtrace.runtime.jit import nb
from subtrace.trace.bezier import COUNTED, FAN
from subtrace.trace.prims import NOT_YET
from subtrace.trace.tris import TRI

PIECE = 0  # item kind of a Catmull-Clark Bezier piece (cells: 1, counted when built)
MAX_STACK = 4 * 64  # nodes pending in one tree walk (three siblings a level, 64 levels)


@nb.njit(cache=True)
def _fan_size(i, j, pd, depth, sides, srow):
    """Triangles of cell (i, j) of a piece's depth-``pd`` grid (``depth`` in its patch's
    units): two, or a fan of one triangle per boundary sample where a side is sampled more
    finely (as ``trace.bezier._leaf`` cuts it)."""
    N = 1 << pd
    n = 4
    extra = False
    for side in range(4):
        on = (j == 0, i == N - 1, j == N - 1, i == 0)[side]
        if on and sides[srow, side] > depth:
            n += (1 << (sides[srow, side] - depth)) - 1
            extra = True
    return n if extra else 2


@nb.njit(cache=True)
def _walk(roots, childs, datas, it, leaf, tri, depth, sides, st_node, st_pos, par):
    """Cells of item ``it`` held by any of the memos (``roots[t]``, ``childs[t]``,
    ``datas[t]``), each counted once, in triangles; ``leaf`` is the level of its cells."""
    T = len(roots)
    total = 0
    any_root = False
    counted = False
    for t in range(T):
        # (a memo that never took a round has no room for the items built since)
        r = roots[t][it] if it < len(roots[t]) else -1
        st_node[0, t] = r
        any_root |= r >= 0
        counted |= r == COUNTED
    if not any_root:
        if counted:  # a one-cell item, evaluated per ray and counted once per thread
            return 1 if tri else _fan_size(0, 0, 0, depth, sides, it)
        return 0
    st_pos[0, 0], st_pos[0, 1], st_pos[0, 2] = 0, 0, 0
    sp = 1
    while sp > 0:
        sp -= 1
        ci, cj, lev = st_pos[sp, 0], st_pos[sp, 1], st_pos[sp, 2]
        if lev == leaf:
            stored = fan = False
            for t in range(T):
                m = st_node[sp, t]
                if m >= 0:
                    d = datas[t][m]
                    stored |= d >= 0
                    fan |= d == FAN
            if stored:
                total += 1 if tri else 2
            elif fan:
                total += _fan_size(ci, cj, leaf, depth, sides, it)
            continue
        for t in range(T):  # the parent's nodes, before its children overwrite its row
            par[t] = st_node[sp, t]
        for q in range(4):
            some = False
            for t in range(T):
                m = par[t]
                c = childs[t][m] + q if m >= 0 and childs[t][m] >= 0 else -1
                st_node[sp, t] = c
                some |= c >= 0
            if some:
                st_pos[sp, 0] = 2 * ci + (q & 1)
                st_pos[sp, 1] = 2 * cj + (q >> 1)
                st_pos[sp, 2] = lev + 1
                sp += 1
    return total


@nb.njit(cache=True)
def distinct_cells(roots, childs, datas, kind, depth_i, level, sides):
    """Triangles of the cells held by the memos ``roots``, ``childs``, ``datas`` (tuples,
    one array per memo), each cell counted once, over every item of kind piece or TRI."""
    T = len(roots)
    st_node = np.empty((MAX_STACK, T), np.int64)
    st_pos = np.empty((MAX_STACK, 3), np.int64)
    par = np.empty(T, np.int64)
    total = 0
    for it in range(len(kind)):
        tri = kind[it] == TRI
        if tri or kind[it] == PIECE:
            # (one call with a run-time flag: a constant True / False at two call sites
            # compiled _walk once per literal; a Loop piece's tree starts at its level:
            # depth - level levels to its cells, as a Catmull-Clark piece's)
            total += _walk(roots, childs, datas, it, depth_i[it] - level[it], tri,
                           depth_i[it], sides, st_node, st_pos, par)
    return total


def thread_correction(memos, iso) -> int:
    """What to add to the per-ray sum of micro-triangles built so that each cell held by
    the threads' memos (``memos.m``, :class:`~subtrace.trace.pools.Memo` tuples) counts once,
    not once per thread that evaluated it: their union's count less each memo's own. ``iso``:
    the pieces' :class:`~subtrace.trace.pools.PieceArrays`."""
    m = memos.m
    args = (iso.kind, iso.depth_i, iso.level, iso.side)
    union = distinct_cells(tuple(x.root for x in m), tuple(x.child for x in m),
                           tuple(x.data for x in m), *args)
    # each memo alone, as a tuple of the same length whose other memos are empty: one
    # compiled distinct_cells per thread count, not one more for 1-tuples
    empty = np.zeros(0, np.int64)
    own = 0
    for k in range(len(m) if len(m) > 1 else 0):
        alone = [(x.root, x.child, x.data) if j == k else (empty, empty, empty)
                 for j, x in enumerate(m)]
        own += distinct_cells(*(tuple(a[f] for a in alone) for f in range(3)), *args)
    return int(union - own) if len(m) > 1 else 0
