"""The shading normal of a hit on a cell (of an irregular patch): the blend of the cell's
exact corner normals, or, where a corner's normal lies more than
``config.CELL_NORMAL_SPREAD_DEG`` from that blend, the exact limit normal at the hit's
parameter (``shade.exact_cell_normals``). Checked against ``Cage.evaluate`` (the limit
surface, OpenSubdiv-checked in tests/test_oracle.py) on OpenSubdiv's rook, whose
semi-sharp creases of sharpness 6-8 are narrower than its cells at 1 px: the blend alone
errs up to 70 degrees there."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from shared_data import small_scene

import subtrace
from subtrace import config
from subtrace.io.scene import apply_overrides
from subtrace.render import render_scene

ROOK = Path(__file__).resolve().parents[1] / "models" / "opensubdiv" / "catmark_rook.obj"


@pytest.fixture(scope="module")
def rook():
    cage = subtrace.load_cage(ROOK)
    lo, hi = cage.bounds()
    return cage, 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))


def _render(rook, view, spread=None, monkeypatch=None):
    cage, centre, size = rook
    if spread is not None:
        monkeypatch.setattr(config, "CELL_NORMAL_SPREAD_DEG", spread)
    eye = centre + size * np.asarray(view)
    scene = apply_overrides(small_scene([ROOK], eye, centre, width=240, height=180, fov=40.0),
                            samples=1)
    return eye, render_scene(scene, cages=[cage]).channels


def _angles(cage, ch):
    """Per hit pixel, the angle (degrees) between its N channel and the limit normal at its
    (patch_id, u, v)."""
    hit = ch["A"] > 0
    uv = np.stack([ch["u"][hit], ch["v"][hit]], axis=1).astype(np.float64)
    _, du, dv = cage.evaluate(ch["patch_id"][hit].astype(np.int64), np.clip(uv, 0.0, 1.0))
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1)[:, None]
    N = np.stack([ch[k][hit] for k in ("N.X", "N.Y", "N.Z")], axis=1).astype(np.float64)
    N /= np.linalg.norm(N, axis=1)[:, None]
    return np.degrees(np.arccos(np.clip(np.abs((n * N).sum(axis=1)), 0.0, 1.0)))


@pytest.mark.parametrize("view", [(0.5, 0.9, 1.3), (1.2, 0.3, -0.8)])
def test_normals_across_high_sharpness_creases_are_the_limit_normals(rook, view,
                                                                      monkeypatch):
    cage = rook[0]
    _, ch = _render(rook, view)
    angle = _angles(cage, ch)
    assert len(angle) > 5000
    assert angle.max() < config.CELL_NORMAL_SPREAD_DEG + 1.0, angle.max()
    assert np.percentile(angle, 99) < 4.0 and np.median(angle) < 0.1
    # the blend alone is far off across the creases: the check above can fail
    _, ch = _render(rook, view, 180.0, monkeypatch)
    assert _angles(cage, ch).max() > 30.0


def test_pixels_given_the_exact_normal_are_coloured_by_it(rook):
    """A headlight-only render colours its hits in the shading pass; those the exact normal
    replaced are coloured again: every hit's R is the albedo times |N . d| (d from the eye
    to its P)."""
    eye, ch = _render(rook, (0.5, 0.9, 1.3))
    hit = ch["A"] > 0
    N = np.stack([ch[k][hit] for k in ("N.X", "N.Y", "N.Z")], axis=1).astype(np.float64)
    d = np.stack([ch[k][hit] for k in ("P.X", "P.Y", "P.Z")], axis=1) - eye
    d /= np.linalg.norm(d, axis=1)[:, None]
    expect = 0.8 * np.abs((N * d).sum(axis=1))
    np.testing.assert_allclose(ch["R"][hit], expect, atol=2e-3)


def test_the_closed_form_across_a_crease_is_the_limit_normal(rook, monkeypatch):
    """``crease.crease_normals`` (a patch along one crease of one sharpness: B-spline
    along, the crease curve split at the parameter across until its sharpness runs out)
    against ``Cage.evaluate`` at random points of every such patch of the rook, half of
    them within 5 % of the crease: the same normal to rounding, the same orientation; the
    other patches are not taken. (``Cage.evaluate`` takes the closed form itself where it
    applies: the reference is its descent through topology alone, ``crease.ENABLED``
    False.)"""
    from subtrace.patches import crease
    from subtrace.patches.table import build_patch_table

    cage = rook[0]
    table = build_patch_table([cage])
    o = table.objects[0]
    irregular = np.nonzero(table.is_quad & ~table.regular)[0]
    rng = np.random.default_rng(7)
    p = np.repeat(irregular, 6)
    uv = rng.random((len(p), 2))
    uv[::2, 1] *= 0.05
    ok, n = crease.crease_normals(o.level, o.points, cage.options, table.face[p], uv)
    served = crease.crease_faces(o.level, cage.options, table.face[p])[0]
    np.testing.assert_array_equal(ok, served)
    assert 0 < ok.sum() < len(p)
    assert (n[~ok] == 0).all()
    ptex_uv = table.ptex_uv0[p[ok]] + table.ptex_scale[p[ok]][:, None] * uv[ok]
    monkeypatch.setattr(crease, "ENABLED", False)
    _, du, dv = cage.evaluate(table.ptex[p[ok]], ptex_uv)
    ref = np.cross(du, dv)
    a = n[ok] / np.linalg.norm(n[ok], axis=1)[:, None]
    b = ref / np.linalg.norm(ref, axis=1)[:, None]
    np.testing.assert_allclose(a, b, atol=1e-9)
