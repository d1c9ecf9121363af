"""Image textures at the hits: a material's maps (MTL `map_Kd`, `map_Ks`, `map_Bump` /
`bump`, `norm`; a scene object's ``*_texture`` keys) looked up at each hit's exact UV,
filtered over the hit's ray-cone footprint from the texture's MIP levels.

* Each image is made once into a tiled, MIP-mapped texture (OpenImageIO's make_texture)
  in the kernel cache's base folder (``runtime.jit.cache_base()/textures``), under a name
  keyed by the file's path, modification time and size; colour maps (diffuse, specular)
  of 8- or 16-bit images are decoded from sRGB to linear there, float images and the
  bump and normal maps are taken as they are. Its MIP levels are read from that file once
  per process, as float32 (:func:`pyramid`). A file that is missing or that OpenImageIO
  cannot read is one warning naming it and where it was given (the MTL or scene line),
  and the material keeps its constant colour.
* A hit's UV is the cage's exact face-varying limit UV at its ptex point
  (``Cage.evaluate_uv``: OpenSubdiv's rules); its Jacobian over the ptex parameter is a
  forward difference of the same evaluation (a step of ``UV_STEP`` inside the face).
* The filter: a ray's cone is one pixel wide (``pixel_angle`` t at distance t); where it
  meets the surface its footprint is an ellipse, the cone's width across and that over the
  cosine of the incidence along the ray's projection (``FOOTPRINT_MIN_COS`` bounds the
  stretch). Its two axes are taken to the ptex parameter through the surface's tangents
  dP/du, dP/dv at the hit (:func:`_tangents_task`: the exact derivatives of a Bezier
  piece's or a Loop net's polynomial, a cell's bilinear ones) and to UV space through the
  UV Jacobian. A Numba kernel filters the MIP levels over them as OpenImageIO's
  TextureSystem's anisotropic MIP-map filter does (:func:`_lookup_task`: the level from
  the minor axis, up to ``ANISOTROPY`` bilinear probes along the major one, two levels
  mixed), on the render's threads; tests/test_textures.py checks it against the
  TextureSystem. Far texture is averaged over its footprint (no shimmer), near texture
  stays sharp.
* Lighting takes per ray the diffuse colour (the map, times the material's Kd where the
  MTL says so, or the scene's ``color`` where given) and the specular colour alike
  (``shade.light``'s ``texel``); bump maps (a height of ``bump_scale`` per unit of the
  map's value, along the normal) and tangent-space normal maps (OpenGL's convention: +x
  along +u, +y along +v; the tangents are dP/du, dP/dv taken through the UV Jacobian's
  inverse) turn the eye-facing shading normal. The N channel keeps the exact limit
  normal.

Array layout: ``texel`` (n,6) float32, per ray: diffuse R, G, B then specular R, G, B,
-1 in columns 0 / 3 where a ray takes its patch's constant colour.
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
import warnings
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from subtrace.errors import SubtraceWarning
from subtrace.geometry.kinds import BEZIER, CELL, LOOP_CELL, TRI
from subtrace.patches.basis import bez_derivatives
from subtrace.patches.evaluate import ptex_starts
from subtrace.runtime.jit import cache_base, leaf_njit, llvm_inline_njit, nb
from subtrace.runtime.threads import run_tasks
from subtrace.shade import C_N, own_ptex, pixel_rays
from subtrace.subdiv.facevarying import FVAR_ALL
from subtrace.trace.pools import Hits, PieceArrays
from subtrace.geometry.tris import tri_derivatives

SLOTS = ("diffuse", "specular", "bump", "normal")
UV_STEP = 2.0 ** -16  # the ptex step of the UV Jacobian's forward difference
FOOTPRINT_MIN_COS = 1e-3  # the footprint's stretch along the ray at most 1 / this
ANISOTROPY = 32  # OpenImageIO's most probes along a footprint's major axis
TEXEL_COLUMNS = 6


class Prepared(NamedTuple):
    """A texture made ready for lookups: its map, the tiled MIP-mapped file, its size."""

    map: object  # subtrace.io.obj.TextureMap
    file: str
    width: int
    height: int
    channels: int


class Textures(NamedTuple):
    """The textures of a patch table: ``patch_set`` (P,) int32, each patch's set (-1:
    none); per set, ``sets[k]`` a dict slot -> :class:`Prepared` and ``tint[k]`` whether
    its diffuse / specular maps are multiplied by the patch's constant colours."""

    patch_set: np.ndarray
    sets: tuple
    tint: tuple


_WARNED: set = set()  # (where, path) of the textures warned about in this process


def texture_sets(table, overrides) -> Textures | None:
    """The textures of ``table``'s patches: each object's scene textures
    (``overrides[object id].textures``, replacing the cage's maps of their slots) over its
    materials' maps; None where no patch has one that could be read."""
    patch_set = np.full(table.n_patches, -1, np.int32)
    sets, tint, keys = [], [], {}
    for oid, o in enumerate(table.objects):
        over = overrides[oid]
        scene_maps = {m.slot: m for m in (over.textures if over is not None else ())}
        mats = list(o.cage.materials)
        sl = slice(o.first_patch, o.first_patch + o.n_patches)
        mat = table.material[sl]
        for k in sorted(set(mat.tolist())):
            maps = {m.slot: (m, True) for m in (mats[k].maps if 0 <= k < len(mats) else ())}
            if "bump" in maps and over is not None and over.bump_scale is not None:
                m, tinted = maps["bump"]
                maps["bump"] = (replace(m, bump_scale=over.bump_scale), tinted)
            for slot, m in scene_maps.items():
                base = over.color if slot == "diffuse" else over.specular
                maps[slot] = (m, base is not None)
            ready = {s: p for s, (m, _) in maps.items() if (p := prepare(m)) is not None}
            if not ready:
                continue
            if o.cage.uv is None:
                _warn_once(("uv", oid, k),
                           f"{next(iter(ready.values())).map.where}: textures need texture "
                           "coordinates (vt) on every face corner; the cage has none, its "
                           "constant colours are used")
                continue
            key = tuple((s, p.file, maps[s][1]) for s, p in sorted(ready.items()))
            if key not in keys:
                keys[key] = len(sets)
                sets.append(ready)
                tint.append({s: maps[s][1] for s in ready})
            patch_set[sl][mat == k] = keys[key]
    if not sets:
        return None
    return Textures(patch_set, tuple(sets), tuple(tint))


def _warn_once(key, message) -> None:
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(message, SubtraceWarning, stacklevel=3)


def texture_folder() -> Path:
    """Where the tiled MIP-mapped textures are kept: ``textures`` in the kernel cache's
    base folder (``runtime.jit.cache_base``)."""
    return cache_base() / "textures"


def prepare(tmap) -> Prepared | None:
    """``tmap`` (a :class:`subtrace.io.obj.TextureMap`) as a tiled MIP-mapped texture in
    :func:`texture_folder`, made on first use (OpenImageIO's make_texture; sRGB colour maps
    decoded to linear); None, with one warning naming the file and where it was given,
    where it is missing or unreadable."""
    import OpenImageIO as oiio

    what = "constant colour" if tmap.slot in ("diffuse", "specular") else "exact normal"
    fail = f"{tmap.where}: texture '{tmap.path}' not read ({{}}); the {tmap.slot} keeps its {what}"
    try:
        st = os.stat(tmap.path)
    except OSError as err:
        _warn_once((tmap.where, tmap.path),
                   fail.format("no such file" if isinstance(err, FileNotFoundError)
                               else err.strerror or str(err)))
        return None
    colour = tmap.slot in ("diffuse", "specular")
    key = f"{os.path.abspath(tmap.path)}|{st.st_mtime_ns}|{st.st_size}|{colour}"
    out = texture_folder() / (hashlib.sha256(key.encode()).hexdigest()[:24] + ".tx")
    if not out.is_file():
        inp = oiio.ImageInput.open(tmap.path)
        if inp is None:
            _warn_once((tmap.where, tmap.path), fail.format(_oiio_error(oiio)))
            return None
        fmt = str(inp.spec().format)
        inp.close()
        config = oiio.ImageSpec()
        if colour and fmt not in ("float", "half", "double"):
            config.attribute("maketx:incolorspace", "sRGB")
            config.attribute("maketx:outcolorspace", "linear")
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f"{out.stem}.{os.getpid()}.tmp.tx")
        ok = oiio.ImageBufAlgo.make_texture(oiio.MakeTxTexture, tmap.path, str(tmp), config)
        if not ok:
            tmp.unlink(missing_ok=True)
            _warn_once((tmap.where, tmap.path), fail.format(_oiio_error(oiio)))
            return None
        os.replace(tmp, out)
    pyr = pyramid(str(out))
    if pyr is None:
        _warn_once((tmap.where, tmap.path), fail.format(_oiio_error(oiio)))
        return None
    return Prepared(tmap, str(out), int(pyr.levels[0, 1]), int(pyr.levels[0, 2]), pyr.channels)


def _oiio_error(oiio) -> str:
    message = oiio.geterror().strip().splitlines()
    return message[0] if message else "OpenImageIO cannot read it"


class Pyramid(NamedTuple):
    """A texture's MIP levels as its tiled file holds them, in float32 (8- and 16-bit
    files' values over 255 / 65535, as OpenImageIO's TextureSystem reads them): ``texels``
    (N,) every level's texels one after the other, each level row by row from the top
    (OpenImageIO's t = 0) and channels interleaved; ``levels`` (L,3) int64 each level's
    first texel's index in ``texels``, its width and height, the finest first;
    ``channels`` the file's channel count. Kept for the process: 4/3 of the image's
    texels in float32 (Spot's 1024 x 1024 RGB: 16 MB; a 4096 x 4096 RGBA: 358 MB)."""

    texels: np.ndarray
    levels: np.ndarray
    channels: int


_PYRAMIDS: dict = {}  # tiled file -> its Pyramid, read once per process
_PYRAMIDS_LOCK = threading.Lock()


def pyramid(file: str) -> Pyramid | None:
    """The MIP levels of the tiled MIP-mapped ``file`` (:func:`prepare`'s), read once per
    process (OpenImageIO's ImageInput, each MIP level of subimage 0); None where OpenImageIO
    cannot read it."""
    with _PYRAMIDS_LOCK:
        if file not in _PYRAMIDS:
            _PYRAMIDS[file] = _read_pyramid(file)
        return _PYRAMIDS[file]


def _read_pyramid(file: str) -> Pyramid | None:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(file)
    if inp is None:
        return None
    try:
        chunks, levels, channels = [], [], inp.spec().nchannels
        start, m = 0, 0
        while inp.seek_subimage(0, m):
            spec = inp.spec()
            pixels = inp.read_image(0, m, 0, channels, oiio.FLOAT)
            if pixels is None or spec.nchannels != channels:
                return None
            pixels = np.asarray(pixels, np.float32).reshape(spec.height, spec.width, channels)
            chunks.append(pixels.ravel())
            levels.append((start, spec.width, spec.height))
            start += pixels.size
            m += 1
    finally:
        inp.close()
    if not levels:
        return None
    return Pyramid(np.concatenate(chunks), np.array(levels, np.int64), channels)


# --------------------------------------------------------------------------------------
# the hits' UVs, tangents and footprints
# --------------------------------------------------------------------------------------


class HitFrames(NamedTuple):
    """Per textured ray (m rows, ``rays`` its index): its UV and what the filter and the
    normal maps need."""

    rays: np.ndarray  # (m,) int64
    st: np.ndarray  # (m,2) float64: the exact limit UV (OBJ's vt: v up)
    jac: np.ndarray  # (m,2,2) float64: d(u_tex, v_tex) / d(ptex u, v)
    dpdu: np.ndarray  # (m,3) float64: dP / d(ptex u)
    dpdv: np.ndarray  # (m,3) float64


def hit_frames(table, hits, iso, patches, rays) -> HitFrames:
    """The exact UVs, UV Jacobians and surface tangents of ``rays`` (their hits in
    ``hits``, a :class:`~subtrace.trace.pools.Hits`, on the items of ``iso``)."""
    m = len(rays)
    tangents = np.zeros((m, 6))
    run_tasks(_tangents_task, tuple(hits), tuple(iso), patches.scale, rays, tangents)
    p = -hits.prim[rays].astype(np.int64) - 2
    ab = np.stack([hits.a[rays], hits.b[rays]], axis=1)
    at = np.clip(patches.uv0[p] + patches.scale[p][:, None] * ab, 0.0, 1.0)
    st, jac = np.full((m, 2), np.nan), np.zeros((m, 2, 2))
    oid = table.object_id[p]
    for o in sorted(set(oid.tolist())):
        sel = np.nonzero(oid == o)[0]
        cage = table.objects[o].cage
        st[sel], jac[sel] = cage_uvs(cage, own_ptex(cage, patches.ptex[p[sel]]), at[sel])
    return HitFrames(np.asarray(rays, np.int64), st, jac, tangents[:, :3], tangents[:, 3:])


def cage_uvs(cage, face, x):
    """The limit UVs (m,2) of ``cage`` at ptex points (``face`` (m,), ``x`` (m,2)) and their
    Jacobians (m,2,2) over the ptex parameter. The linear mode (FVAR_ALL: the bilinear
    interpolation of the face's corner values, a ptex sub-face of an n-gon's between its
    corner, the edge midpoints and the centroid, a Loop triangle's linear one, as
    ``Cage.evaluate_uv``) in closed form in :func:`_linear_uv_task`; the others by
    ``Cage.evaluate_uv`` and a forward difference inside the face (``UV_STEP``)."""
    m = len(face)
    st, jac = np.full((m, 2), np.nan), np.zeros((m, 2, 2))
    if cage.uv.mode == FVAR_ALL:
        starts = ptex_starts(cage)
        base = np.searchsorted(starts, face, side="right") - 1
        fo = cage.face_offsets
        sub = np.where(np.diff(fo)[base] == cage.options.regular_face_size, -1,
                       face - starts[base])
        run_tasks(_linear_uv_task, fo, cage.uv.values, cage.uv.face_values.astype(np.int64),
                  base, sub, x, cage.scheme == "loop", cage.base.face_hole, st, jac)
        return st, jac
    loop = cage.scheme == "loop"
    room = x[:, 0] + x[:, 1] + UV_STEP <= 1.0 if loop else None
    hu = np.where(room if loop else x[:, 0] + UV_STEP <= 1.0, UV_STEP, -UV_STEP)
    hv = np.where(room if loop else x[:, 1] + UV_STEP <= 1.0, UV_STEP, -UV_STEP)
    pts = np.concatenate([x, x + np.stack([hu, 0 * hu], 1), x + np.stack([0 * hv, hv], 1)])
    uv = cage.evaluate_uv(np.tile(face, 3), pts).reshape(3, m, 2)
    st[:] = uv[0]
    jac[:, :, 0] = (uv[1] - uv[0]) / hu[:, None]
    jac[:, :, 1] = (uv[2] - uv[0]) / hv[:, None]
    return st, jac


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _linear_uv_task(task, n_tasks, fo, values, fvals, base, sub, x, loop, hole, st, jac):
    """The linear mode's UVs and Jacobians (see :func:`cage_uvs`) of samples ``task,
    task + n_tasks, ...``: corners c0 .. c3 of the ptex face's bilinear map (c0, c1, c2 a
    Loop triangle's), NaN on holes."""
    for k in range(task, len(base), n_tasks):
        f = base[k]
        if hole[f]:
            st[k, 0] = st[k, 1] = np.nan
            continue
        a, n = fo[f], fo[f + 1] - fo[f]
        u, v = x[k, 0], x[k, 1]
        for d in range(2):
            if loop:
                c0, c1, c2 = values[fvals[a], d], values[fvals[a + 1], d], values[fvals[a + 2], d]
                st[k, d] = (1.0 - u - v) * c0 + u * c1 + v * c2
                jac[k, d, 0] = c1 - c0
                jac[k, d, 1] = c2 - c0
                continue
            if sub[k] < 0:
                c0, c1 = values[fvals[a], d], values[fvals[a + 1], d]
                c2, c3 = values[fvals[a + 2], d], values[fvals[a + 3], d]
            else:  # (a sub-face of an n-gon: its corner, the midpoints, the centroid)
                j = sub[k]
                c0 = values[fvals[a + j], d]
                c1 = 0.5 * (c0 + values[fvals[a + (j + 1) % n], d])
                c3 = 0.5 * (c0 + values[fvals[a + (j + n - 1) % n], d])
                c2 = 0.0
                for i in range(n):
                    c2 += values[fvals[a + i], d]
                c2 /= n
            st[k, d] = ((1 - u) * (1 - v) * c0 + u * (1 - v) * c1 + u * v * c2
                        + (1 - u) * v * c3)
            jac[k, d, 0] = (1 - v) * (c1 - c0) + v * (c2 - c3)
            jac[k, d, 1] = (1 - u) * (c3 - c0) + u * (c2 - c1)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _tangents_task(task, n_tasks, hits_t, iso_t, scale, rays, out):
    """dP/du and dP/dv (over the ptex parameter) at the hits of ``rays`` (thread ``task``'s
    share, every ``n_tasks``-th) into ``out`` (m,6): a Bezier piece's and a Loop net's
    exact derivatives, a cell's bilinear (a Loop cell's linear) ones from its corners."""
    hits, iso = Hits(*hits_t), PieceArrays(*iso_t)
    for k in range(task, len(rays), n_tasks):
        r = rays[k]
        p = -np.int64(hits.prim[r]) - 2
        u, v = hits.a[r], hits.b[r]
        it = np.int64(hits.item[r])
        c = iso.ref[it]
        kind = iso.kind[it]
        if kind == BEZIER or kind == TRI:
            sc = np.float64(1 << iso.level[it])
        else:
            sc = np.float64(np.int64(1) << np.int64(hits.leaf[r]))
        lu, lv = u * sc - iso.i0[it], v * sc - iso.j0[it]
        if kind == BEZIER:
            pu, pv = bez_derivatives(iso.nets[c], lu, lv)
            du = (pu[0], pu[1], pu[2])
            dv = (pv[0], pv[1], pv[2])
        elif kind == TRI:
            g = np.float64(iso.orient[it])
            ps, pt = tri_derivatives(iso.tri_nets, c, g * lu, g * lv)
            sc *= g
            du = (ps[0], ps[1], ps[2])
            dv = (pt[0], pt[1], pt[2])
        elif kind == CELL:
            q = iso.cells[4 * c:4 * c + 4]
            du = ((1 - lv) * (q[1, 0] - q[0, 0]) + lv * (q[2, 0] - q[3, 0]),
                  (1 - lv) * (q[1, 1] - q[0, 1]) + lv * (q[2, 1] - q[3, 1]),
                  (1 - lv) * (q[1, 2] - q[0, 2]) + lv * (q[2, 2] - q[3, 2]))
            dv = ((1 - lu) * (q[3, 0] - q[0, 0]) + lu * (q[2, 0] - q[1, 0]),
                  (1 - lu) * (q[3, 1] - q[0, 1]) + lu * (q[2, 1] - q[1, 1]),
                  (1 - lu) * (q[3, 2] - q[0, 2]) + lu * (q[2, 2] - q[1, 2]))
        elif kind == LOOP_CELL:
            q = iso.cells[4 * c:4 * c + 3]
            sc *= np.float64(iso.orient[it])
            du = (q[1, 0] - q[0, 0], q[1, 1] - q[0, 1], q[1, 2] - q[0, 2])
            dv = (q[2, 0] - q[0, 0], q[2, 1] - q[0, 1], q[2, 2] - q[0, 2])
        else:
            continue
        f = sc / scale[p]  # (the item's parameter -> the patch's -> the ptex face's)
        for d in range(3):
            out[k, d] = du[d] * f
            out[k, 3 + d] = dv[d] * f


def footprints(frames, t, dirs, pixel_angle):
    """The UV-space axes (m,2) and (m,2) of each ray's cone footprint at its hit (see the
    module comment): the major axis (along the ray's projection) and the minor one."""
    major, minor = np.empty((len(t), 2)), np.empty((len(t), 2))
    run_tasks(_footprint_task, frames.dpdu, frames.dpdv, frames.jac, np.asarray(t, np.float64),
              np.ascontiguousarray(dirs, np.float64), float(pixel_angle), major, minor)
    return major, minor


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _footprint_task(task, n_tasks, pu, pv, jac, t, d, pixel_angle, major, minor):
    """:func:`footprints` of rays ``task, task + n_tasks, ...``: the cone's width
    ``pixel_angle t`` across the ray and that over the incidence's cosine along its
    projection on the tangent plane, each taken to the ptex parameter (least squares on
    dP/du, dP/dv) and to UV space (the Jacobian)."""
    for k in range(task, len(t), n_tasks):
        a = (pu[k, 0], pu[k, 1], pu[k, 2])
        b = (pv[k, 0], pv[k, 1], pv[k, 2])
        n = _unit(_cross(a, b))
        dk = (d[k, 0], d[k, 1], d[k, 2])
        width = t[k] * pixel_angle
        cos = abs(_dot(dk, n))
        across = _cross(n, dk)
        if _dot(across, across) < 1e-18:  # (along the normal: any tangent)
            across = a
        across = _unit(across)
        along = _cross(across, n)
        stretch = width / max(cos, FOOTPRINT_MIN_COS)
        g00, g01, g11 = _dot(a, a), _dot(a, b), _dot(b, b)
        det = g00 * g11 - g01 * g01
        if not abs(det) > 0.0:
            det = np.inf
        for e, s, out in ((along, stretch, major), (across, width, minor)):
            b0, b1 = _dot(a, e) * s, _dot(b, e) * s
            da = (g11 * b0 - g01 * b1) / det
            db = (g00 * b1 - g01 * b0) / det
            out[k, 0] = jac[k, 0, 0] * da + jac[k, 0, 1] * db
            out[k, 1] = jac[k, 1, 0] * da + jac[k, 1, 1] * db


@leaf_njit
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@leaf_njit
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@leaf_njit
def _unit(a):
    n = math.sqrt(_dot(a, a))
    if not n > 0.0:
        return a
    return (a[0] / n, a[1] / n, a[2] / n)


def lookup(prep, st, major, minor, channels):
    """(m, channels) float32: texture ``prep`` filtered over the footprints (``major``,
    ``minor``: UV axes (m,2)) at the UVs ``st`` (m,2) (OBJ's v up; the map's -s, -o and
    -clamp applied), from its MIP levels (:func:`pyramid`) by :func:`filter_levels`."""
    return filter_levels(pyramid(prep.file), prep.map, st, major, minor, channels)


def filter_levels(pyr, tmap, st, major, minor, channels):
    """:func:`lookup` on the MIP levels ``pyr`` (a :class:`Pyramid`) of map ``tmap``: the
    footprints' axes and the UVs taken by the map's -s and -o to OpenImageIO's (s, t) (t
    down from the top), then :func:`_lookup_task` on the render's threads. The channels
    read are ``tmap.channel`` on for a bump map, 0 on for the others; past the file's
    channels they are 0, but a grey file's one channel fills R, G and B (OpenImageIO's
    ``gray_to_rgb``)."""
    first = tmap.channel if tmap.slot == "bump" else 0
    gray = pyr.channels == 1 and first == 0 and channels >= 3
    chan = np.array([0 if gray and c < 3 else (first + c if first + c < pyr.channels else -1)
                     for c in range(channels)], np.int64)
    xform = np.array([tmap.scale[0], tmap.scale[1], tmap.offset[0], tmap.offset[1]],
                     np.float64)
    out = np.empty((len(st), channels), np.float32)
    c64 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
    run_tasks(_lookup_task, pyr.texels, pyr.levels, np.int64(pyr.channels), chan, c64(st),
              c64(major), c64(minor), xform, not tmap.clamp, np.int64(ANISOTROPY), out)
    return out


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _lookup_task(task, n_tasks, texels, levels, nch, chan, st, major, minor, xform,
                 periodic, anisotropy, out):
    """The filtered texture of rays ``task, task + n_tasks, ...`` into ``out`` (m, channels),
    as OpenImageIO's TextureSystem filters a MIP-mapped texture (its default MIP mode,
    bilinear within a level, ``conservative_filter``):

    * the footprint's axes (``major``, ``minor``: UV, the map's -s / -o applied here, t
      down) give the ellipse they span (the lengths ``lmaj`` >= ``lmin`` of its principal
      axes, from its quadratic form as in Greene's and Heckbert's EWA; for orthogonal axes
      their own lengths), ``anisotropy`` the most its aspect may be: past it the major
      axis is the mean of itself and ``anisotropy`` times the minor one, and the minor that
      over ``anisotropy`` (a little blur across, a little aliasing along);
    * the MIP level: the first whose smaller side makes the minor axis at most a texel
      (``f = lmin * min(width, height) <= 1``) and the one before it, mixed
      ``2 f - 1`` : ``2 - 2 f`` (clamped); the finest alone where even it is too coarse
      (then a minor axis under half its texel takes the aspect from the major axis alone),
      the coarsest alone where it still is too fine;
    * along the major axis ``max(1, int(2 aspect - 1))`` bilinear probes at ``p_i (lmaj -
      lmin)`` from the centre, ``p_i = 2 (i + 0.5) / n - 1``, weighted ``exp(-2 x_i^2)``,
      ``x_i = p_i lmaj / (2 (lmaj - lmin))`` and normalised (1 or 2 probes: equal weights);
    * a bilinear probe at (s, t) reads the texels around (s width - 1/2, t height - 1/2),
      their indices repeated periodically (``periodic``) or clamped to the edge.

    Each ray's texel depends on its own inputs alone: any thread count gives the same
    bits. A ray whose UV is not finite gets 0."""
    nout = len(chan)
    acc = np.zeros(nout)
    pos = np.zeros(2 * anisotropy)
    wts = np.zeros(2 * anisotropy)
    for k in range(task, len(st), n_tasks):
        s = st[k, 0] * xform[0] + xform[2]
        t = 1.0 - (st[k, 1] * xform[1] + xform[3])
        for c in range(nout):
            out[k, c] = 0.0
        if not (math.isfinite(s) and math.isfinite(t)):
            continue
        dsdx, dtdx = major[k, 0] * xform[0], -major[k, 1] * xform[1]
        dsdy, dtdy = minor[k, 0] * xform[0], -minor[k, 1] * xform[1]
        lmaj, lmin, dir_s, dir_t, aspect = _ellipse(dsdx, dtdx, dsdy, dtdy, anisotropy)
        lev0, lev1, blend, aspect = _mip_levels(levels, lmaj, lmin, aspect, anisotropy)
        n = _probes(lmaj, lmin, aspect, pos, wts)
        sm, tm = dir_s * (lmaj - lmin), dir_t * (lmaj - lmin)
        for c in range(nout):
            acc[c] = 0.0
        for side in range(2):
            lev = lev0 if side == 0 else lev1
            weight = 1.0 - blend if side == 0 else blend
            if weight == 0.0:
                continue
            base, w, h = levels[lev, 0], levels[lev, 1], levels[lev, 2]
            for i in range(n):
                _bilinear(texels, base, w, h, nch, chan, s + pos[i] * sm, t + pos[i] * tm,
                          periodic, weight * wts[i], acc)
        for c in range(nout):
            out[k, c] = acc[c]


@llvm_inline_njit
def _ellipse(dsdx, dtdx, dsdy, dtdy, anisotropy):
    """(lmaj, lmin, dir_s, dir_t, aspect) of the footprint with axes (dsdx, dtdx), (dsdy,
    dtdy) (see :func:`_lookup_task`): its principal axes' lengths, the major one's
    direction and the aspect, past ``anisotropy`` clamped to it."""
    # (degenerate axes: a tiny one orthogonal to the other, or a tiny round footprint)
    eps = 1e-8
    dx2, dy2 = dsdx * dsdx + dtdx * dtdx, dsdy * dsdy + dtdy * dtdy
    if not dx2 >= eps * eps:
        if not dy2 >= eps * eps:
            dsdx, dtdx, dsdy, dtdy = eps, 0.0, 0.0, eps
        else:
            f = eps / math.sqrt(dy2)
            dsdx, dtdx = dtdy * f, -dsdy * f
    elif not dy2 >= eps * eps:
        f = eps / math.sqrt(dx2)
        dsdy, dtdy = -dtdx * f, dsdx * f
    qa = dtdx * dtdx + dtdy * dtdy
    qb = -2.0 * (dsdx * dtdx + dsdy * dtdy)
    qc = dsdx * dsdx + dsdy * dsdy
    root = math.sqrt((qa - qc) * (qa - qc) + qb * qb)
    big, small = 0.5 * (qa + qc + root), 0.5 * (qa + qc - root)
    lmaj = min(math.sqrt(big) if big > 0.0 else 0.0, 1000.0)
    lmin = min(math.sqrt(small) if small > 0.0 else 0.0, 1000.0)
    # (the major axis's direction, up to its sign, which neither the probes nor their
    # weights see: the angle atan2(qb, qa - qc) / 2 + pi / 2 by the half-angle rules)
    if root > 0.0:
        cos2 = (qa - qc) / root
        dir_s = math.sqrt(max(0.5 - 0.5 * cos2, 0.0))
        dir_t = math.sqrt(max(0.5 + 0.5 * cos2, 0.0))
        if qb > 0.0:
            dir_s = -dir_s
    else:
        dir_s, dir_t = 0.0, 1.0
    aspect = lmaj / lmin
    if not aspect >= 1.0:
        aspect = 1.0
    aspect = min(aspect, 1e6)
    if aspect > anisotropy:
        aspect = np.float64(anisotropy)
        lmaj = 0.5 * (lmaj + lmin * anisotropy)
        lmin = lmaj / anisotropy
    return lmaj, lmin, dir_s, dir_t, aspect


@llvm_inline_njit
def _mip_levels(levels, lmaj, lmin, aspect, anisotropy):
    """(lev0, lev1, blend, aspect): the two MIP levels of ``levels`` a footprint of axes
    ``lmaj`` >= ``lmin`` takes, the second's weight and the aspect (the finest level's
    rule for a minor axis under half its texel; see :func:`_lookup_task`)."""
    n_levels = len(levels)
    for m in range(n_levels):
        f = lmin * min(levels[m, 1], levels[m, 2])
        if f <= 1.0:
            if m > 0:
                return m - 1, m, min(max(2.0 * f - 1.0, 0.0), 1.0), aspect
            r = max(levels[0, 1], levels[0, 2])
            if lmin * r < 0.5:
                aspect = min(max(lmaj * r * 2.0, 1.0), np.float64(anisotropy))
            return 0, 0, 0.0, aspect
    return n_levels - 1, n_levels - 1, 0.0, aspect


@llvm_inline_njit
def _probes(lmaj, lmin, aspect, pos, wts):
    """The number n of probes along the major axis, their places ``pos[:n]`` (-1..1 of
    ``lmaj - lmin`` from the centre) and normalised weights ``wts[:n]`` (see
    :func:`_lookup_task`)."""
    n = max(1, int(2.0 * aspect - 1.0))
    if n == 1:
        pos[0], wts[0] = 0.0, 1.0
    elif n == 2:
        pos[0], pos[1], wts[0], wts[1] = -0.5, 0.5, 0.5, 0.5
    else:
        # (exp(-2 x_i^2) over that of the first probe: x_i is linear in i, so each ratio
        # to the one before is the one before's times a constant)
        scale = lmaj / (2.0 * (lmaj - lmin))
        step = 2.0 / n
        g = -2.0 * scale * scale * step
        p = step * 0.5 - 1.0
        ratio = math.exp(g * (2.0 * p + step))
        turn = math.exp(2.0 * g * step)
        wt, total = 1.0, 0.0
        for i in range(n):
            pos[i], wts[i] = p + i * step, wt
            total += wt
            wt *= ratio
            ratio *= turn
        for i in range(n):
            wts[i] /= total
    return n


@llvm_inline_njit
def _bilinear(texels, base, w, h, nch, chan, s, t, periodic, weight, acc):
    """Add ``weight`` times the bilinear lookup at (s, t) of the level at ``base`` (w x h
    texels of ``nch`` channels) to ``acc`` (channels ``chan``, -1: none)."""
    x, y = s * w - 0.5, t * h - 0.5
    fx, fy = math.floor(x), math.floor(y)
    ax, ay = x - fx, y - fy
    i0, j0 = np.int64(fx), np.int64(fy)
    i1, j1 = i0 + 1, j0 + 1
    if periodic:  # (a power of two's remainder by a mask: no division)
        i0 = i0 & (w - 1) if w & (w - 1) == 0 else i0 % w
        j0 = j0 & (h - 1) if h & (h - 1) == 0 else j0 % h
        i1 = i0 + 1 if i0 + 1 < w else 0
        j1 = j0 + 1 if j0 + 1 < h else 0
    else:
        i0, i1 = min(max(i0, 0), w - 1), min(max(i1, 0), w - 1)
        j0, j1 = min(max(j0, 0), h - 1), min(max(j1, 0), h - 1)
    r0, r1 = base + j0 * w * nch, base + j1 * w * nch
    a00, a01 = r0 + i0 * nch, r0 + i1 * nch
    a10, a11 = r1 + i0 * nch, r1 + i1 * nch
    for c in range(len(chan)):
        q = chan[c]
        if q < 0:
            continue
        top = texels[a00 + q] + ax * (texels[a01 + q] - texels[a00 + q])
        bottom = texels[a10 + q] + ax * (texels[a11 + q] - texels[a10 + q])
        acc[c] += weight * (top + ay * (bottom - top))


# --------------------------------------------------------------------------------------
# the shading of the textured rays
# --------------------------------------------------------------------------------------


def no_texel() -> np.ndarray:
    """(0, 6) float32: no ray textured (``shade.light``'s ``texel``)."""
    return np.zeros((0, TEXEL_COLUMNS), np.float32)


def texture_hits(textures, table, hits, iso, patches, frame, width, dirs, pixel_angle,
                 normals, planes) -> np.ndarray | None:
    """Texture the hits of ``hits`` on patches with textures (``textures``:
    :func:`texture_sets`; None: none): returns ``texel`` (n,6) float32 (the module comment)
    and turns ``normals`` (n,3), the eye-facing shading normals, by the bump and normal
    maps. ``dirs``: None (ray r is pixel r's centre ray) or the rays' (n,3) directions;
    ``pixel_angle``: a pixel's angle in radians (the rays' cone); ``planes``: the shading's
    planes (their N channel: the normal before the maps)."""
    if textures is None or table is None:
        return None
    n = len(hits.t)
    hit = np.nonzero(hits.t < np.inf)[0]
    p = -hits.prim[hit].astype(np.int64) - 2
    ks = textures.patch_set[p]
    rays = hit[ks >= 0]
    ks = ks[ks >= 0]
    if not len(rays):
        return None
    texel = np.full((n, TEXEL_COLUMNS), -1.0, np.float32)
    frames = hit_frames(table, hits, iso, patches, rays)
    if dirs is None:
        d = pixel_rays(frame, width, rays)
    else:
        d = np.asarray(dirs)[rays]
    major, minor = footprints(frames, hits.t[rays], d, pixel_angle)
    prow = -hits.prim[rays].astype(np.int64) - 2
    for k in sorted(set(ks.tolist())):
        sel = np.nonzero(ks == k)[0]
        ready, tint = textures.sets[k], textures.tint[k]
        for slot, col, base in (("diffuse", 0, patches.color), ("specular", 3, patches.specular)):
            if slot in ready:
                c = lookup(ready[slot], frames.st[sel], major[sel], minor[sel], 3)
                if tint[slot]:
                    c = c * base[prow[sel]]
                texel[rays[sel], col:col + 3] = c
        if "bump" in ready or "normal" in ready:
            _turn_normals(ready, frames, sel, major, minor, normals, planes, rays)
    return texel


def _turn_normals(ready, frames, sel, major, minor, normals, planes, rays) -> None:
    """The eye-facing shading normals of rays ``rays[sel]`` turned by the bump map and then
    the normal map of ``ready`` (see the module comment)."""
    r = rays[sel]
    n0 = planes[C_N:C_N + 3, r].T.astype(np.float64)  # (the exact normal, not eye-facing)
    face = np.where((n0 * normals[r]).sum(axis=1) < 0.0, -1.0, 1.0)
    pu, pv, jac = frames.dpdu[sel], frames.dpdv[sel], frames.jac[sel]
    n = n0
    if "bump" in ready:
        prep = ready["bump"]
        st = frames.st[sel]
        # a step of the footprint's width, at least a texel, in u and in v
        step = np.maximum(np.linalg.norm(minor[sel], axis=1),
                          1.0 / max(prep.width, prep.height))
        h = [lookup(prep, st + off, major[sel], minor[sel], 1)[:, 0].astype(np.float64)
             for off in (np.zeros((len(sel), 2)), np.stack([step, 0 * step], 1),
                         np.stack([0 * step, step], 1))]
        hs, ht = (h[1] - h[0]) / step, (h[2] - h[0]) / step
        bm = prep.map.bump_scale
        ha = bm * (hs * jac[:, 0, 0] + ht * jac[:, 1, 0])  # d(height)/d(ptex u)
        hb = bm * (hs * jac[:, 0, 1] + ht * jac[:, 1, 1])
        side = np.where((np.cross(pu, pv) * n).sum(axis=1) < 0.0, -1.0, 1.0)
        m = np.cross(pu + ha[:, None] * n, pv + hb[:, None] * n) * side[:, None]
        n = m / np.maximum(np.linalg.norm(m, axis=1), 1e-300)[:, None]
    if "normal" in ready:
        prep = ready["normal"]
        c = lookup(prep, frames.st[sel], major[sel], minor[sel], 3).astype(np.float64)
        x, y, z = (2.0 * c[:, k] - 1.0 for k in range(3))
        # the tangents along +u and +v of the texture: [dP/du dP/dv] J^-1
        det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        det = np.where(np.abs(det) > 0.0, det, np.inf)
        ps = (pu * jac[:, 1, 1][:, None] - pv * jac[:, 1, 0][:, None]) / det[:, None]
        pt = (pv * jac[:, 0, 0][:, None] - pu * jac[:, 0, 1][:, None]) / det[:, None]
        tan = ps - (ps * n).sum(axis=1)[:, None] * n
        tan /= np.maximum(np.linalg.norm(tan, axis=1), 1e-300)[:, None]
        bit = np.cross(n, tan)
        bit *= np.where((bit * pt).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
        m = x[:, None] * tan + y[:, None] * bit + z[:, None] * n
        n = m / np.maximum(np.linalg.norm(m, axis=1), 1e-300)[:, None]
    good = np.isfinite(n).all(axis=1) & (np.abs(n).sum(axis=1) > 0.0)
    normals[r[good]] = n[good] * face[good][:, None]
