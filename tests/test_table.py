"""subtrace.patches.table: the patch table against its plain construction (every patch's
one-ring shell, then the regular patches' Bezier nets and bounds over it, the basis's public
functions), bit for bit, for one and several objects and any thread count."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from subtrace import config, load_cage
from subtrace.errors import SubtraceWarning
from subtrace.patches.basis import bezier_nets, net_bounds
from subtrace.patches.bspline import control_grids, control_points, regular_mask
from subtrace.patches.criterion import subdominant
from subtrace.patches.shells import one_ring_shells
from subtrace.patches.table import build_patch_table
from subtrace.runtime import threads as tasks

SHARED = Path(__file__).resolve().parents[2] / "shared"
SHAPES = SHARED / "oracle" / "shapes"
NAMES = ["catmark_chaikin1", "catmark_cube_creases1", "catmark_nonman_verts", "catmark_hole_test2",
         "catmark_nonquads", "catmark_edgenone", "loop_chaikin1", "loop_saddle_edgecorner"]
pytestmark = pytest.mark.skipif(not SHAPES.is_dir(), reason="../shared/oracle not present")


def _load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SubtraceWarning)
        return load_cage(SHAPES / f"{name}.obj")


def plain_shells(o):
    """(shell_min, shell_max, edge_bound, rate, regular, nets) of one object, built plainly."""
    lev, pts, faces = o.level, o.points, o.patch_faces
    smin, smax, ebound, valence = one_ring_shells(lev, faces, pts)
    if o.cage.options.chaikin and np.any(lev.edge_sharpness > 1.0):
        margin = config.SHELL_CHAIKIN_MARGIN * (smax - smin).max(axis=1, keepdims=True)
        smin -= margin
        smax += margin
    rate = subdominant(valence, o.cage.scheme == "catmark")
    regular = regular_mask(lev, o.cage.options, faces)
    nets = bezier_nets(control_points(lev, faces[regular], pts))
    smin[regular], smax[regular], ebound[regular] = net_bounds(nets)
    rate[regular] = 0.5
    return smin, smax, ebound, rate, regular, nets


@pytest.mark.parametrize("threads", [1, 2])
def test_table_matches_its_plain_construction(threads):
    cages = [_load(name) for name in NAMES]
    tasks.set_threads(threads)
    try:
        tables = [build_patch_table([c]) for c in cages] + [build_patch_table(cages)]
    finally:
        tasks.set_threads(None)
    fields = ("shell_min", "shell_max", "edge_bound", "rate", "regular", "nets")
    for table in tables:
        for o in table.objects:
            sl = slice(o.first_patch, o.first_patch + len(o.patch_faces))
            want = plain_shells(o)
            first_net = int(np.count_nonzero(table.regular[: o.first_patch]))
            for name, array in zip(fields, want):
                got = getattr(table, name)
                got = got[first_net : first_net + len(array)] if name == "nets" else got[sl]
                assert got.tobytes() == array.tobytes(), (o.cage.path, name)
            # each side's edge, global over the objects (-1 pads a triangle's 4th side)
            k = 4 if o.cage.scheme == "catmark" else 3
            lev, faces = o.level, o.patch_faces
            edges = lev.face_edges[lev.face_offsets[faces][:, None] + np.arange(k)] + o.first_edge
            assert np.array_equal(table.edges[sl, :k], edges)
            assert (table.edges[sl, k:] == -1).all()
        for name in ("shell_min", "nets", "edges", "ptex_uv0"):
            assert getattr(table, name).flags.c_contiguous, name


def test_control_grids_on_two_tasks_equal_one(monkeypatch):
    """control_grids split over two tasks (blocks of faces) gathers what one task does."""
    from subtrace.patches import bspline

    path = SHARED / "models" / "spot_control_mesh.obj"
    if not path.exists():
        pytest.skip(f"{path} not present")
    cage = load_cage(path)
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
