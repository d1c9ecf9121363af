"""subtrace.patches.table: the patch table against its plain construction (every patch's
one-ring shell, then the regular patches' Bezier nets and bounds over it, the basis's public
functions), bit for bit, for one and several objects and any thread count."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from shared_data import MODELS, SHAPES

from subtrace import config, load_cage
from subtrace.errors import SubtraceWarning
from subtrace.patches.basis import bezier_nets, net_bounds
from subtrace.patches.bspline import control_grids, control_points, regular_mask
from subtrace.patches.criterion import subdominant
from subtrace.patches.evaluate import ptex_layout
from subtrace.patches.shells import one_ring_shells
from subtrace.patches.table import build_patch_table
from subtrace.runtime import threads as tasks

NAMES = ["catmark_chaikin1", "catmark_cube_creases1", "catmark_nonman_verts", "catmark_hole_test2",
         "catmark_nonquads", "catmark_edgenone", "loop_chaikin1", "loop_saddle_edgecorner"]


def _load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SubtraceWarning)
        return load_cage(SHAPES / f"{name}.obj")


def plain_shells(lev, pts, faces, cage):
    """(shell_min, shell_max, edge_bound, rate, regular, nets) of patches ``faces`` of
    ``lev``, built plainly."""
    smin, smax, ebound, valence = one_ring_shells(lev, faces, pts)
    if cage.options.chaikin and np.any(lev.edge_sharpness > 1.0):
        margin = config.SHELL_CHAIKIN_MARGIN * (smax - smin).max(axis=1, keepdims=True)
        smin -= margin
        smax += margin
    rate = subdominant(valence, cage.scheme == "catmark")
    regular = regular_mask(lev, cage.options, faces)
    nets = bezier_nets(control_points(lev, faces[regular], pts))
    smin[regular], smax[regular], ebound[regular] = net_bounds(nets)
    rate[regular] = 0.5
    return smin, smax, ebound, rate, regular, nets


def plain_cage_quads(cage):
    """The faces of a Catmull-Clark cage that are patches themselves, one by one: regular
    quads (``regular_mask``) whose corners' faces are all quads."""
    base = cage.base
    if cage.scheme != "catmark":
        return np.zeros(0, np.int64)
    out = []
    regular = regular_mask(base, cage.options, np.arange(base.n_faces))
    for f in range(base.n_faces):
        if not regular[f] or base.face_hole[f]:
            continue
        corners = base.face_verts[base.face_offsets[f]:base.face_offsets[f + 1]]
        around = [g for v in corners
                  for g in base.vert_faces[base.vert_face_offsets[v]:base.vert_face_offsets[v + 1]]]
        if all(base.face_offsets[g + 1] - base.face_offsets[g] == 4 for g in around):
            out.append(f)
    return np.array(out, np.int64)


@pytest.mark.parametrize("threads", [1, 2])
def test_table_matches_its_plain_construction(threads):
    cages = [_load(name) for name in NAMES]
    tasks.set_threads(threads)
    try:
        tables = [build_patch_table([c]) for c in cages] + [build_patch_table(cages)]
    finally:
        tasks.set_threads(None)
    fields = ("shell_min", "shell_max", "edge_bound", "rate", "regular", "nets")
    some_quads = False
    for table in tables:
        for o in table.objects:
            assert np.array_equal(o.cage_quads, plain_cage_quads(o.cage))
            some_quads |= len(o.cage_quads) > 0
            # the patch level's faces: the children of the cage's other faces
            if o.cage.scheme == "catmark":
                sizes = np.diff(o.cage.base.face_offsets)
                others = np.ones(o.cage.base.n_faces, bool)
                others[o.cage_quads] = False
                others &= ~o.cage.base.face_hole
                assert len(o.patch_faces) == sizes[others].sum()
            for lev, pts, sl, faces in o.parts():
                want = plain_shells(lev, pts, faces, o.cage)
                first_net = int(np.count_nonzero(table.regular[: sl.start]))
                for name, array in zip(fields, want):
                    got = getattr(table, name)
                    got = got[first_net : first_net + len(array)] if name == "nets" else got[sl]
                    assert got.tobytes() == array.tobytes(), (o.cage.path, name)
            _check_edges(table, o)
        for name in ("shell_min", "nets", "edges", "ptex_uv0"):
            assert getattr(table, name).flags.c_contiguous, name
    assert some_quads


def _check_edges(table, o):
    """Each side's edge, global over the objects (-1 pads a triangle's 4th side): the patch
    level's own, but a cage edge (after the patch level's) where a side of a cage quad patch
    lies on it, with the shift 1 for the patch level's sides there."""
    k = 4 if o.cage.scheme == "catmark" else 3
    lev, faces = o.level, o.patch_faces
    sl = slice(o.first_patch, o.first_patch + len(faces))
    want = lev.face_edges[lev.face_offsets[faces][:, None] + np.arange(k)] + o.first_edge
    shift = np.zeros((len(faces), 4), np.int8)
    base = o.cage.base
    if len(o.cage_quads):
        quad_edges = set(base.face_edges[base.face_offsets[o.cage_quads][:, None]
                                         + np.arange(4)].ravel().tolist())
        # the child at corner j of cage face F (from its ptex placement) has the cage's
        # corner j at its corner j (a quad's children keep its orientation) or 0 (else):
        # its side there lies on the cage edge from corner j, the side before on the one
        # into it
        ptex_face, sub, _ = ptex_layout(o.cage)
        corner_of = {(0.0, 0.0): 0, (0.5, 0.0): 1, (0.5, 0.5): 2, (0.0, 0.5): 3}
        for r in range(len(faces)):
            p = o.first_patch + r
            F = int(ptex_face[table.ptex[p]])
            n = base.face_offsets[F + 1] - base.face_offsets[F]
            j = corner_of[tuple(table.ptex_uv0[p])] if n == 4 else int(sub[table.ptex[p]])
            at = j if n == 4 else 0
            for side, i in ((at, j), ((at - 1) % 4, (j - 1) % n)):
                cage_edge = int(base.face_edges[base.face_offsets[F] + i])
                if cage_edge in quad_edges:
                    want[r, side] = o.first_edge + lev.n_edges + cage_edge
                    shift[r, side] = 1
        sl0 = slice(sl.stop, o.first_patch + o.n_patches)
        want0 = (base.face_edges[base.face_offsets[o.cage_quads][:, None] + np.arange(4)]
                 + o.first_edge + lev.n_edges)
        assert np.array_equal(table.edges[sl0], want0)
        assert (table.side_shift[sl0] == 0).all()
        assert (table.level0[sl0] == 0).all() and table.regular[sl0].all()
    assert np.array_equal(table.edges[sl, :k], want)
    assert (table.edges[sl, k:] == -1).all()
    assert np.array_equal(table.side_shift[sl], shift)


def test_control_grids_on_two_tasks_equal_one(monkeypatch):
    """control_grids split over two tasks (blocks of faces) gathers what one task does."""
    from subtrace.patches import bspline

    cage = load_cage(MODELS / "spot_control_mesh.obj")
    lev = cage.level_topology(2)
    faces = np.nonzero(regular_mask(lev, cage.options, np.arange(lev.n_faces)))[0]
    assert len(faces) > 2 * bspline._GRID_BLOCK
    tasks.set_threads(2)
    try:
        monkeypatch.setattr(bspline, "_GRID_PARALLEL_MIN", 0)
        two = control_grids(lev, faces)
        monkeypatch.setattr(bspline, "_GRID_PARALLEL_MIN", 10**9)
        one = control_grids(lev, faces)
    finally:
        tasks.set_threads(None)
    np.testing.assert_array_equal(two, one)


def test_cut_and_cage_quads_made_once_per_cage():
    """A table of the same faces again (a turntable's next frame) takes the level-1 cut
    and the cage quads the cage keeps, and is the same table; other faces make a new cut."""
    cage = _load("catmark_hole_test2")
    first = build_patch_table([cage])
    assert len(first.objects[0].cage_quads) and len(first.objects[0].patch_faces)
    again = build_patch_table([cage])
    assert again.objects[0].level is first.objects[0].level
    for name in ("face", "edges", "side_shift", "shell_min", "nets", "ptex_uv0"):
        assert getattr(again, name).tobytes() == getattr(first, name).tobytes(), name
    keep = np.ones(cage.n_faces, bool)
    keep[0] = False
    other = build_patch_table([cage], [keep])
    assert other.objects[0].level is not first.objects[0].level
    fresh = build_patch_table([_load("catmark_hole_test2")], [keep])
    for name in ("face", "edges", "shell_min", "nets"):
        assert getattr(other, name).tobytes() == getattr(fresh, name).tobytes(), name
