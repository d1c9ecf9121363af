"""``subtrace info [CAGE.obj] [--scheme S] [--level N]``: the statistics of a control cage.

Owns the cage report (:func:`cage_report`): scheme and options, counts, face sizes,
boundary / non-manifold / isolated elements, creases and sharp vertices, holes, UVs, valences,
extraordinary vertices, Euler characteristic, the cage's bounds and the bounds of the
level-1 limit points, and optionally the counts after N uniform refinements; and the
free-form report (:func:`freeform_report`) of a file's trimmed NURBS surfaces: surfaces and
degrees, Bezier patches after knot insertion, trim loops, trimming curves, Bezier segments
and monotone curve units. A file of free-form surfaces only gets that report alone.
"""

from __future__ import annotations

import numpy as np

from subtrace.cli.common import boundary_code, set_up_numba
from subtrace.config import SHARPNESS_INFINITE
from subtrace.data import sample_cage_path
from subtrace.io.meshes import is_mesh_file
from subtrace.io.obj import read_obj
from subtrace.io.scene import BOUNDARIES
from subtrace.io.usd import is_usd
from subtrace.mesh.cage import cage_from_obj, load_cage
from subtrace.nurbs.freeform import freeform_of

BOUNDARY_NAMES = {code: name for name, code in BOUNDARIES.items()}  # Sdc code -> scene name
SIZE_NAMES = {3: "triangles", 4: "quads", 5: "pentagons", 6: "hexagons"}


def execute(args) -> int:
    """Print the report of ``args.cage`` (the built-in sample cage without one)."""
    set_up_numba(args)
    if args.cage is None:
        path = sample_cage_path()
        label = f"{path} (built-in sample: Spot by Keenan Crane, public domain)"
    else:
        path = args.cage
        label = str(path)
    if is_usd(path) or is_mesh_file(path):
        cage = load_cage(path, scheme=args.scheme, boundary=boundary_code(args))
        rows = [("file", label)] + cage_report(cage, args.level)
    else:
        data = read_obj(path)
        rows = [("file", label)]
        if len(data.face_sizes):
            rows += cage_report(cage_from_obj(data, scheme=args.scheme,
                                              boundary=boundary_code(args)), args.level)
        else:
            rows.append(("faces", "0 (free-form surfaces only)"))
        freeform = freeform_of(data)
        if freeform is not None:
            rows += freeform_report(freeform)
    width = max(len(k) for k, _ in rows) + 1
    for key, value in rows:
        print(f"{key + ':':<{width}} {value}")
    return 0


def cage_report(cage, level: int | None = None) -> list[tuple[str, str]]:
    """The rows ``subtrace info`` prints for ``cage`` (key, value), in order."""
    rows = _scheme_rows(cage)
    base = cage.base
    n_v, n_f, n_e = base.n_verts, base.n_faces, base.n_edges
    rows.append(("vertices", str(n_v)))
    rows.append(("faces", str(n_f)))
    rows.append(("edges", str(n_e)))
    sizes, counts = np.unique(cage.face_sizes, return_counts=True)
    rows.append(
        ("face sizes", ", ".join(f"{_size_name(int(s))} {int(c)}" for s, c in zip(sizes, counts)))
    )
    rows += _feature_rows(base)
    if cage.uv is not None:
        rows.append(("UVs", f"{len(cage.uv.values)} values, face-varying interpolation "
                            f"{cage.uv.mode_name}"))
    else:
        rows.append(("UVs", "none"))

    has_faces = np.diff(base.vert_face_offsets) > 0
    valence = np.diff(base.vert_edge_offsets)
    used = valence[has_faces]
    if len(used):
        rows.append(("valence", f"{int(used.min())}..{int(used.max())}"))
    else:
        rows.append(("valence", "n/a"))
    rows.append(("extraordinary vertices", str(extraordinary_count(cage))))
    rows.append(("Euler characteristic", f"{n_v - n_e + n_f} (V - E + F)"))

    lo, hi = cage.points.min(axis=0), cage.points.max(axis=0)
    rows.append(("cage bounds", _bounds(lo, hi)))
    rows.append(("limit bounds", _limit_bounds(cage)))

    if level is not None:
        lev = cage.level_topology(level)
        rows.append(
            (
                f"level {level}",
                f"{lev.n_verts} vertices, {lev.n_faces} faces, {lev.n_edges} edges, "
                f"Euler characteristic {lev.n_verts - lev.n_edges + lev.n_faces}",
            )
        )
    return rows


def _scheme_rows(cage) -> list[tuple[str, str]]:
    """The scheme and its options (boundary mode, crease method, triangle rule)."""
    opts = cage.options
    scheme_name = "Catmull-Clark" if cage.scheme == "catmark" else "Loop"
    if cage.scheme == "catmark":
        tri_rule = "smooth" if opts.smooth_triangles else "catmark"
    else:
        tri_rule = "n/a (Loop)"
    return [
        ("scheme", f"{cage.scheme} ({scheme_name})"),
        (
            "options",
            f"boundary {BOUNDARY_NAMES.get(opts.boundary, str(opts.boundary))}, "
            f"crease method {'chaikin' if opts.chaikin else 'uniform'}, "
            f"triangle rule {tri_rule}",
        ),
    ]


def _feature_rows(base) -> list[tuple[str, str]]:
    """Boundary, non-manifold and isolated elements, creases, sharp vertices and holes of
    the base level's topology."""
    rows: list[tuple[str, str]] = []
    edge_uses = np.diff(base.edge_face_offsets)
    has_faces = np.diff(base.vert_face_offsets) > 0
    interior_manifold_edge = (edge_uses == 2) & ~base.edge_nonmanifold
    # boundary: one incident face; degenerate edges (a face repeating a vertex) also have
    # one, but OpenSubdiv treats them as non-manifold, and so are they counted here
    boundary_edge = (edge_uses == 1) & ~base.edge_nonmanifold
    rows.append(("boundary edges", str(int(np.count_nonzero(boundary_edge)))))
    rows.append(
        (
            "non-manifold",
            f"{int(np.count_nonzero(base.edge_nonmanifold))} edges, "
            f"{int(np.count_nonzero(~base.vert_manifold & has_faces))} vertices",
        )
    )
    rows.append(("isolated vertices", str(int(np.count_nonzero(~has_faces)))))

    # creases: interior manifold edges with a tag (boundary / non-manifold edges are sharp
    # anyway, so a tag on them changes nothing and is not counted)
    s_e = base.edge_sharpness[interior_manifold_edge]
    n_inf = int(np.count_nonzero(s_e >= SHARPNESS_INFINITE))
    n_semi = int(np.count_nonzero((s_e > 0) & (s_e < SHARPNESS_INFINITE)))
    rows.append(
        ("crease edges", f"{n_inf + n_semi} ({n_semi} semi-sharp, {n_inf} infinitely sharp)")
    )
    s_v = base.vert_sharpness
    n_vinf = int(np.count_nonzero(s_v >= SHARPNESS_INFINITE))
    n_vsemi = int(np.count_nonzero((s_v > 0) & (s_v < SHARPNESS_INFINITE)))
    rows.append(
        (
            "sharp vertices",
            f"{n_vinf + n_vsemi} ({n_vsemi} semi-sharp, {n_vinf} infinitely sharp; corner "
            "tags plus automatic corners / non-manifold vertices)",
        )
    )
    rows.append(("hole faces", str(int(np.count_nonzero(base.face_hole)))))
    return rows


def _size_name(size: int) -> str:
    return SIZE_NAMES.get(size, f"{size}-gons")


def extraordinary_count(cage) -> int:
    """Manifold vertices whose valence is not the regular one of the scheme.

    Regular valence: 4 (Catmark) / 6 (Loop) for interior vertices, 3 / 4 on a boundary;
    boundary vertices with a single face (corners) count as regular. Non-manifold and
    isolated vertices are reported separately and not counted here.
    """
    base = cage.base
    reg = 4 if cage.scheme == "catmark" else 6
    valence = np.diff(base.vert_edge_offsets)
    n_faces = np.diff(base.vert_face_offsets)
    boundary = valence == n_faces + 1
    regular = np.where(boundary, (valence == reg // 2 + 1) | (n_faces == 1), valence == reg)
    return int(np.count_nonzero(base.vert_manifold & (n_faces > 0) & ~regular))


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _bounds(lo, hi) -> str:
    return f"min {_fmt(lo)} max {_fmt(hi)} size {_fmt(hi - lo)}"


def _limit_bounds(cage) -> str:
    try:
        P, _, _ = cage.limit(1)
    except ModuleNotFoundError as exc:  # limit evaluation not part of this build yet
        if exc.name and exc.name.startswith("subtrace"):
            return "n/a (limit evaluation is not available in this build)"
        raise
    # vertices on hole faces only, or on no face at all, are not on the surface
    on_surface = _surface_vertices(cage.level_topology(1))
    if not on_surface.any():
        return "n/a (every face is a hole)"
    P = P[on_surface]
    return _bounds(P.min(axis=0), P.max(axis=0)) + " (limit points of the level-1 vertices)"


def _surface_vertices(lev):
    """(V,) bool: the vertex is a corner of a face that is not a hole."""
    sizes = np.diff(lev.face_offsets)
    corner_in_hole = np.repeat(lev.face_hole, sizes)
    keep = np.zeros(lev.n_verts, dtype=bool)
    keep[lev.face_verts[~corner_in_hole]] = True
    return keep


def freeform_report(freeform) -> list[tuple[str, str]]:
    """The rows ``subtrace info`` prints for a file's free-form content
    (:class:`subtrace.nurbs.freeform.FreeForm`)."""
    from subtrace.nurbs.surface import bezier_patches
    from subtrace.nurbs.trim import monotone_units

    surfaces = freeform.surfaces
    rational = sum(s.rational for s in surfaces)
    rows = [("free-form surfaces", f"{len(surfaces)} ({rational} rational, "
                                   f"{len(surfaces) - rational} polynomial)")]
    degrees: dict = {}
    for s in surfaces:
        degrees[s.degree] = degrees.get(s.degree, 0) + 1
    rows.append(("surface degrees", ", ".join(
        f"{du}x{dv}: {count}" for (du, dv), count in sorted(degrees.items()))))
    patches = [len(bezier_patches(s)[0]) for s in surfaces]
    rows.append(("Bezier patches", f"{sum(patches)} (knot insertion; "
                                   f"{min(patches)}..{max(patches)} per surface)"))
    outer = sum(not lp.hole for s in surfaces for lp in s.loops)
    holes = sum(lp.hole for s in surfaces for lp in s.loops)
    trimmed = sum(bool(s.loops) for s in surfaces)
    rows.append(("trim loops", f"{outer} outer, {holes} holes ({trimmed} of {len(surfaces)} "
                               "surfaces trimmed)"))
    loops = [lp for s in surfaces for lp in s.loops]
    segments = sum(len(lp.segments) for lp in loops)
    units = len(monotone_units(loops)) if loops else 0
    rows.append(("trim curves", f"{len(freeform.curves)} curv2, {segments} Bezier segments in "
                                f"loops, {units} monotone curve units"))
    points = np.concatenate([s.control.reshape(-1, 4) for s in surfaces])
    xyz = points[:, :3] / points[:, 3:]
    rows.append(("free-form bounds", _bounds(xyz.min(axis=0), xyz.max(axis=0))
                 + " (control points: the surfaces lie inside)"))
    return rows
