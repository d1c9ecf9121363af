"""Reflections: the rays a reflective material sends, traced to their closest hit, shaded
there and added to the colour of the ray that met it (the picture's step after the
lighting: ``picture._colour``).

A material reflects where it asks to (``shade.material_of``: a scene object's
``metallic`` / ``roughness``, MTL's ``Pm`` / ``Pr``, or MTL's ``illum`` 3..7 with ``Ks``
the reflection's colour and ``Ns`` its gloss): its patches' ``reflect`` (the reflectance
at normal incidence F0, 0 for the others) and ``roughness`` (GGX alpha = roughness^2).
The colour of a shaded ray of view v and normal n (towards the viewer) becomes

    D (1 - F(n.v)) + S + R

D the lighting ``shade.light`` gave it (Lambert, Blinn-Phong, ambient occlusion), F
Schlick's Fresnel term F0 + (1 - F0)(1 - cos)^5, S the GGX lobe's light from every lamp
and the headlight (with the shadow rays' visibility the lighting used: nothing for a
mirror, whose lobe no lamp of zero size meets) and R the reflected rays' radiance: a mirror
(roughness 0) sends one ray along the mirror direction, weighted by F(n.v); a glossy
material ``[render] reflection_samples`` rays (default 8), their microfacet normals drawn
from GGX's distribution of visible normals (Heitz 2018: importance sampled, each weighted
by F(v.h) G2 / G1(v) / samples). Their points are those of the R2 sequence of the pixel,
turned by its hash, as a sphere light's shadow rays (``lights``): an edge pixel's
anti-aliasing rays continue its sequence, so its gloss is stratified over all its rays,
and nothing depends on the thread count or the tiles. Materials that do not reflect keep
their colour bit for bit (this step does not touch their rays).

The units are the lighting's: a white Lambertian surface under a light of irradiance E
shows E (``shade.light`` takes the BRDF as the albedo, not albedo / pi), so a surface's
pixel is pi times its radiance, and a reflected ray brings back pi times the radiance it
meets: a surface's pixel value where it meets one, an environment light's pi L (what a
white diffuse surface shows under a constant sky L: in a white furnace a white mirror and
a white diffuse surface look alike), and where it meets nothing and there is no
environment, the background as the picture shows it (one colour; a gradient at the
height the direction would have in the picture: its elevation over the view's horizontal
plane, top above the picture, bottom below).

A reflected ray leaves its hit displaced along the normal by the hit's error bound (as a
shadow ray: ``shade.error_bound``) and finds its closest hit in the scene's aggregate
(``aggregate.SceneAggregate.closest``): among the cages (the BVH of the shells,
``trace.rays.trace_rays``, which refines what it meets by the narrowest cone that can
reach it, ``patches.shells.Sight``) and the free-form surfaces (with its own cone: its
path's length from the eye times the tolerance, as the aggregate's shadow rays carry
theirs), and an opaque ground (a shadow catcher is the background: a miss). There it is
shaded as a camera ray would be (Lambert and Blinn-Phong under every lamp, with shadow
rays: ``shade.visibility_at``; the headlight along the ray; no ambient occlusion), and a
reflective hit reflects again, one ray, up to ``[render] reflection_depth`` bounces
(default 1); past the last its reflection is what a ray along its mirror direction would
meet beyond everything (the environment or the background).
"""

from __future__ import annotations

import math
import time

import numpy as np

from subtrace.lights import ENVIRONMENT, KEY_STRIDE, R2_A1, R2_A2, RGB, environment_radiance
from subtrace.lights import environment_irradiance, hash01, irradiance_at, is_environment
from subtrace.runtime.jit import leaf_njit, nb
from subtrace.shade import C_R, error_bound, pixel_rays, visibility_at

MIN_ALPHA = 1e-4  # GGX alpha at least (roughness 0.01): a narrower lobe is a mirror


def reflects(patches) -> bool:
    """Whether any patch of ``patches`` (``shade.PatchShading``) reflects."""
    return patches is not None and bool(len(patches.reflect)) and bool(
        patches.reflect.max() > 0.0)


def scene_reflects(scene, cages, nurbs=None) -> bool:
    """Whether a material of the scene may reflect (its reflected rays reach what no view
    bounds: the render culls nothing and chooses the depths for secondary rays): an
    object's ``metallic`` / ``roughness``, a cage's material that reflects, a free-form
    surface's."""
    if any(o.roughness is not None for o in scene.objects):
        return True
    if any(m.roughness is not None for c in cages for m in getattr(c, "materials", ())):
        return True
    return nurbs is not None and bool(nurbs.surface_reflect.max(initial=0.0) > 0.0)


def mirror_pass(scene, camera, frame, width, lights, headlight, world, patches, tol_rad,
                ground, trace_shadows, stats):
    """``reflect(t, normals, pix_patch, planes, dirs, keys, visible)``: the reflections of
    the rays from the eye (pixel centres, or ``dirs``) whose hits reflect, added to their
    colour in ``planes`` (see the module comment); ``visible``: the lamps' visibility the
    lighting used (``shade.shadow_visibility``), ``keys``: each ray's key
    (``lights.ray_keys``). ``camera``: the whole image's (the background's gradient);
    ``width``: the picture's (its pixels' rays); ``world``: the scene's cages and free-form
    surfaces (``aggregate.SceneAggregate``), where the reflected rays find their closest
    hits (and their image textures, over their cones widened along the path from the eye);
    ``ground``: (unit up, height) or None; ``trace_shadows``: the picture's any-hit
    shadow rays (blocked)."""
    ctx = _Context(scene, camera, lights, headlight, world, patches, tol_rad, ground,
                   trace_shadows)

    def reflect(t, normals, pix_patch, planes, dirs, keys, visible):
        t0 = time.perf_counter()
        r = np.nonzero(pix_patch >= 0)[0]
        r = r[patches.reflect[pix_patch[r]].max(axis=1) > 0.0]
        if not len(r):
            return
        d = pixel_rays(frame, width, r) if dirs is None else dirs[r]
        key = np.zeros(len(r), np.int64) if keys is None else keys[r]
        vis = visible[:, r] if visible.shape[1] else visible
        colour, n_rays = ctx.primary(frame[0], t[r], d, np.ascontiguousarray(normals[r]),
                                     pix_patch[r], key, vis,
                                     planes[C_R:C_R + 3, r].T.astype(np.float64))
        planes[C_R:C_R + 3, r] = colour.T
        stats.reflection_rays += n_rays
        stats.time_reflections += time.perf_counter() - t0

    return reflect


class _Context:
    """What the reflected rays need of the picture (see :func:`mirror_pass`)."""

    def __init__(self, scene, camera, lights, headlight, world, patches, tol_rad, ground,
                 trace_shadows):
        r = scene.render
        self.lights, self.headlight, self.world = lights, float(headlight), world
        self.patches, self.tol_rad = patches, float(tol_rad)
        self.ground, self.blocked = ground, trace_shadows
        self.depth, self.samples = int(r.reflection_depth), int(r.reflection_samples)
        self.ground_color = None if ground is None or scene.ground.color is None else \
            np.asarray(scene.ground.color, np.float64)
        self.escape = _escape(scene, camera)

    # -- the rays from the eye ----------------------------------------------------------

    def primary(self, eye, t, d, f, patch, key, vis, lit):
        """The colour (n,3) of the reflective hits of the rays ``eye + t d`` (unit ``d``,
        normals ``f`` towards the eye, patches ``patch``, keys ``key``, the lamps'
        visibility ``vis`` (L, n) or (L, 0), lit colour ``lit`` (n,3)) and the number of
        reflected rays traced."""
        p = self.patches
        q = eye + t[:, None] * d
        f0 = np.ascontiguousarray(p.reflect[patch])
        alpha = np.maximum(p.roughness[patch] ** 2, 0.0)
        glossy = alpha >= MIN_ALPHA
        alpha = np.where(glossy, np.maximum(alpha, MIN_ALPHA), 0.0)
        # the lobe's light from the lamps, and the Fresnel term that scales the lit colour
        none = np.zeros((len(t), 3))
        direct, fres = _shade(self, q, f, d, none, none, np.zeros(len(t)), f0, alpha, vis,
                              False)
        colour = lit * (1.0 - fres) + direct
        if self.depth == 0:  # (no reflected rays: what lies beyond along the mirror)
            mirror = d - 2.0 * (d * f).sum(axis=1)[:, None] * f
            return colour + fres * self.escape(mirror), 0
        length = t  # (the path from the eye: the cone's width at the hit is t tol_rad)
        m = np.where(glossy, self.samples, 1).astype(np.int64)
        n_rays = self._bounces(q, f, d, f0, alpha, key, m, length, np.ones((len(t), 3)),
                               np.arange(len(t)), colour, 1)
        return colour, n_rays

    # -- the bounces ---------------------------------------------------------------------

    def _bounces(self, q, f, d, f0, alpha, key, m, length, weight, root, out, level):
        """Send the reflected rays of the hits ``q`` (view along ``d``, normals ``f``
        towards it, reflectance ``f0``, GGX ``alpha``, ``m`` rays each, ``weight`` (n,3)
        their throughput, ``root`` the ray of ``out`` each adds to), trace and shade them
        (reflecting again while ``level`` < the depth); returns the rays traced."""
        origin = _offset(q, f, length, self.tol_rad)
        first = np.concatenate([[0], np.cumsum(m)])
        n = int(first[-1])
        dirs, w = np.empty((n, 3)), np.empty((n, 3))
        _lobe_rays(np.ascontiguousarray(-d), f, f0, alpha, key, m, first, level, dirs, w)
        src = np.repeat(np.arange(len(q)), m)
        keep = np.nonzero(w.max(axis=1) > 0.0)[0]  # (a sample below the horizon: none)
        src, dirs, w = src[keep], dirs[keep], w[keep] * weight[src[keep]]
        o, ray_root, ray_key = origin[src], root[src], key[src]
        start = length[src]
        s, fn, patch, _, texel = self.world.closest(dirs, o, start)
        hit_ground, sg = self._ground(o, dirs, s)
        # misses (and a shadow catcher): what lies beyond
        miss = np.nonzero(~(s < np.inf) & ~hit_ground)[0]
        np.add.at(out, ray_root[miss], w[miss] * self.escape(dirs[miss]))
        hit = np.nonzero(s < np.inf)[0]
        on_ground = np.nonzero(hit_ground)[0]
        # the hits: their material (the ground's: its colour, no lobe)
        idx = np.concatenate([hit, on_ground])
        if not len(idx):
            return len(dirs)
        dist = np.concatenate([s[hit], sg[on_ground]])
        pt = o[idx] + dist[:, None] * dirs[idx]
        normal = np.concatenate([fn[hit], np.repeat(self.ground[0][None] if len(on_ground)
                                                    else np.zeros((1, 3)), len(on_ground),
                                                    axis=0)])
        p = self.patches
        ph = patch[hit]
        g = len(on_ground)
        gc = self.ground_color if g else np.zeros(3)
        colour = np.concatenate([p.color[ph], np.repeat(gc[None], g, axis=0)])
        spec = np.concatenate([p.specular[ph], np.zeros((g, 3))])
        if texel is not None:  # (the image textures' colours where they cover the hit)
            tx = texel[hit].astype(np.float64)
            colour[:len(hit)] = np.where(tx[:, :1] >= 0.0, tx[:, :3], colour[:len(hit)])
            spec[:len(hit)] = np.where(tx[:, 3:4] >= 0.0, tx[:, 3:], spec[:len(hit)])
        shin = np.concatenate([p.shininess[ph], np.zeros(g)])
        rf = np.concatenate([p.reflect[ph], np.zeros((g, 3))])
        al = np.concatenate([p.roughness[ph] ** 2, np.zeros(g)])
        al = np.where(al >= MIN_ALPHA, np.maximum(al, MIN_ALPHA), 0.0)
        bd = np.ascontiguousarray(dirs[idx])
        bkey = ray_key[idx]
        blen = start[idx] + dist
        vis = self._visibility(pt, normal, blen, bkey)
        local, fres = _shade(self, pt, normal, bd, colour, spec, shin, rf, al, vis, True)
        np.add.at(out, ray_root[idx], w[idx] * local)
        # the reflective hits reflect again, or see what lies beyond along their mirror
        more = np.nonzero(rf.max(axis=1) > 0.0)[0]
        n_rays = len(dirs)
        if not len(more):
            return n_rays
        if level < self.depth:
            n_rays += self._bounces(pt[more], np.ascontiguousarray(normal[more]), bd[more],
                                    np.ascontiguousarray(rf[more]), al[more], bkey[more],
                                    np.ones(len(more), np.int64), blen[more],
                                    w[idx][more], ray_root[idx][more], out, level + 1)
        else:
            mirror = bd[more] - 2.0 * (bd[more] * normal[more]).sum(axis=1)[:, None] * \
                normal[more]
            np.add.at(out, ray_root[idx][more], w[idx][more] * fres[more] * self.escape(mirror))
        return n_rays

    def _ground(self, origins, dirs, s):
        """Which rays meet an opaque ground nearer than ``s`` (n,) bool, and where (n,)."""
        n = len(dirs)
        if self.ground is None or self.ground_color is None:
            return np.zeros(n, bool), np.full(n, np.inf)
        up, height = np.asarray(self.ground[0], np.float64), float(self.ground[1])
        dn = dirs @ up
        with np.errstate(divide="ignore", invalid="ignore"):
            sg = (height - origins @ up) / dn
        on = (dn < 0.0) & (sg > 0.0) & (sg < s)
        return on, np.where(on, sg, np.inf)

    def _visibility(self, q, f, length, key):
        """(L, n) float32: the share of each lamp's shadow rays from the points ``q``
        (normals ``f`` towards the viewer; ``length`` their paths from the eye: the error
        bound) that arrive (1 where none is traced): ``shade.visibility_at``."""
        return visibility_at(self.blocked, q, f, error_bound(q, length, self.tol_rad),
                             self.lights, key)


def _offset(q, f, length, tol_rad):
    """The points ``q`` moved along their normals ``f`` by their error bound (the cell's
    size seen from the eye over the path ``length``, and the point's rounding)."""
    return q + error_bound(q, length, tol_rad)[:, None] * f


def _shade(ctx, q, f, d, colour, spec, shin, f0, alpha, vis, diffuse):
    """:func:`_shade_points` over numpy arrays: (colour (n,3), Fresnel term (n,3))."""
    n = len(q)
    out, fres = np.zeros((n, 3)), np.zeros((n, 3))
    if n:
        _shade_points(np.ascontiguousarray(q), np.ascontiguousarray(f), np.ascontiguousarray(d),
                      np.ascontiguousarray(colour, np.float64), np.ascontiguousarray(spec,
                                                                                     np.float64),
                      np.ascontiguousarray(shin, np.float64), np.ascontiguousarray(f0,
                                                                                   np.float64),
                      np.ascontiguousarray(alpha, np.float64), ctx.lights, ctx.headlight,
                      np.ascontiguousarray(vis, np.float32), diffuse, out, fres)
    return out, fres


def _escape(scene, camera):
    """``escape(dirs)`` -> (n,3): what a reflected ray along ``dirs`` (n,3) meets beyond
    every surface: the environment lights' radiance times pi (nearest pixel of each
    image), or without one the background (see the module comment)."""
    envs = [environment_radiance(light) for light in scene.lights
            if light.kind == ENVIRONMENT]
    r = scene.render
    top = np.asarray(r.background, np.float64)
    bottom = None if r.background_bottom is None else np.asarray(r.background_bottom,
                                                                 np.float64)
    _, up, _ = camera.basis()
    up = np.asarray(up, np.float64)
    tan_half = math.tan(math.radians(camera.fov_deg) / 2.0)

    def escape(dirs):
        dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
        if envs:
            out = np.zeros((len(dirs), 3))
            theta = np.arccos(np.clip(dirs[:, 1], -1.0, 1.0))
            phi = np.arctan2(dirs[:, 0], -dirs[:, 2])
            for image in envs:
                h, w = image.shape[:2]
                row = np.clip((theta / math.pi * h).astype(np.int64), 0, h - 1)
                col = np.mod((((phi / (2.0 * math.pi)) + 0.5) * w).astype(np.int64), w)
                out += math.pi * image[row, col]
            return out
        if bottom is None:
            return np.repeat(top[None], len(dirs), axis=0)
        s = np.clip(dirs @ up, -1.0, 1.0)
        with np.errstate(divide="ignore"):
            tan_phi = s / np.sqrt(np.maximum(1.0 - s * s, 0.0))
        w = np.clip(0.5 - tan_phi / (2.0 * tan_half), 0.0, 1.0)[:, None]
        return (1.0 - w) * top + w * bottom

    return escape


# --------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------


@leaf_njit
def schlick(f0, c):
    """Schlick's Fresnel term of reflectance ``f0`` at normal incidence, at cosine ``c``."""
    x = 1.0 - min(max(c, 0.0), 1.0)
    x2 = x * x
    return f0 + (1.0 - f0) * (x2 * x2 * x)


@leaf_njit
def smith_lambda(c, a2):
    """Smith's Lambda of GGX (alpha^2 ``a2``) for a direction at cosine ``c`` to the normal."""
    c2 = c * c
    if not c2 > 0.0:
        return np.inf
    return 0.5 * (math.sqrt(1.0 + a2 * max(1.0 - c2, 0.0) / c2) - 1.0)


@leaf_njit
def ggx_lobe(fx, fy, fz, vx, vy, vz, lx, ly, lz, a2):
    """pi D(h) G2(v, l) / (4 n.v) of GGX (alpha^2 ``a2``): the lobe's pixel value per unit
    of irradiance and Fresnel term, for the view ``v`` and the unit ``l`` towards the
    light (both unit, the normal ``f``); with the cosine v.h (0, 0 below either horizon)."""
    cv = fx * vx + fy * vy + fz * vz
    cl = fx * lx + fy * ly + fz * lz
    if not (cv > 0.0 and cl > 0.0):
        return 0.0, 0.0
    hx, hy, hz = vx + lx, vy + ly, vz + lz
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if not hn > 0.0:
        return 0.0, 0.0
    ch = (fx * hx + fy * hy + fz * hz) / hn
    vh = (vx * hx + vy * hy + vz * hz) / hn
    k = ch * ch * (a2 - 1.0) + 1.0
    dist = a2 / (math.pi * k * k)
    g2 = 1.0 / (1.0 + smith_lambda(cv, a2) + smith_lambda(cl, a2))
    return math.pi * dist * g2 / (4.0 * cv), vh


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _shade_points(q, f, d, colour, spec, shin, f0, alpha, lights, headlight, vis, diffuse, out,
                  fres):
    """Per point i (``q`` (n,3), seen along the unit ``d``, normal ``f`` towards the
    viewer): ``fres[i]`` the Fresnel term F(n.v) of its reflectance ``f0`` (0 where it
    reflects not) and ``out[i]``: (``diffuse``) the lighting of ``shade.light`` (Lambert
    of ``colour``, Blinn-Phong of ``spec`` and ``shin``, every lamp scaled by ``vis[k, i]``,
    an environment by its irradiance, the headlight along ``d``) times 1 - F, plus the GGX
    lobe (``alpha``; 0: none) of every lamp but an environment and of the headlight."""
    n_l = lights.shape[0]
    for i in range(len(q)):
        fx, fy, fz = f[i, 0], f[i, 1], f[i, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        cv = -(fx * dx + fy * dy + fz * dz)
        shiny = spec[i, 0] > 0.0 or spec[i, 1] > 0.0 or spec[i, 2] > 0.0
        refl = f0[i, 0] > 0.0 or f0[i, 1] > 0.0 or f0[i, 2] > 0.0
        a2 = alpha[i] * alpha[i]
        lr = lg = lb = 0.0  # (Lambert's light)
        sr = sg = sb = 0.0  # (Blinn-Phong's)
        gr = gg = gb = 0.0  # (the GGX lobe's, Fresnel weighted)
        if headlight > 0.0:
            c = max(cv, 0.0) * headlight
            lr += c
            lg += c
            lb += c
            if shiny:
                h = max(cv, 0.0) ** shin[i] * headlight
                sr += h
                sg += h
                sb += h
            if refl and alpha[i] > 0.0:
                g, vh = ggx_lobe(fx, fy, fz, -dx, -dy, -dz, -dx, -dy, -dz, a2)
                g *= headlight
                gr += g * schlick(f0[i, 0], vh)
                gg += g * schlick(f0[i, 1], vh)
                gb += g * schlick(f0[i, 2], vh)
        for k in range(n_l):
            v = vis[k, i] if vis.shape[1] else 1.0
            if is_environment(lights, k):
                if diffuse:
                    er, eg, eb = environment_irradiance(lights, k, fx, fy, fz)
                    lr += er * v * lights[k, RGB]
                    lg += eg * v * lights[k, RGB + 1]
                    lb += eb * v * lights[k, RGB + 2]
                continue
            lx, ly, lz, _, e = irradiance_at(lights, k, q[i, 0], q[i, 1], q[i, 2])
            c = (fx * lx + fy * ly + fz * lz) * e
            if not (c > 0.0 and v > 0.0):
                continue
            c *= v
            lr += c * lights[k, RGB]
            lg += c * lights[k, RGB + 1]
            lb += c * lights[k, RGB + 2]
            if shiny:  # (Blinn-Phong: the half vector of l and -d)
                hx, hy, hz = lx - dx, ly - dy, lz - dz
                hn = math.sqrt(hx * hx + hy * hy + hz * hz)
                ch = (fx * hx + fy * hy + fz * hz) / hn if hn > 0.0 else 0.0
                h = (ch ** shin[i] if ch > 0.0 else 0.0) * e * v
                sr += h * lights[k, RGB]
                sg += h * lights[k, RGB + 1]
                sb += h * lights[k, RGB + 2]
            if refl and alpha[i] > 0.0:
                g, vh = ggx_lobe(fx, fy, fz, -dx, -dy, -dz, lx, ly, lz, a2)
                g *= e * v
                gr += g * schlick(f0[i, 0], vh) * lights[k, RGB]
                gg += g * schlick(f0[i, 1], vh) * lights[k, RGB + 1]
                gb += g * schlick(f0[i, 2], vh) * lights[k, RGB + 2]
        for c in range(3):
            fres[i, c] = schlick(f0[i, c], cv) if refl else 0.0
        if diffuse:
            out[i, 0] = (colour[i, 0] * lr + spec[i, 0] * sr) * (1.0 - fres[i, 0]) + gr
            out[i, 1] = (colour[i, 1] * lg + spec[i, 1] * sg) * (1.0 - fres[i, 1]) + gg
            out[i, 2] = (colour[i, 2] * lb + spec[i, 2] * sb) * (1.0 - fres[i, 2]) + gb
        else:
            out[i, 0], out[i, 1], out[i, 2] = gr, gg, gb


@leaf_njit
def lobe_point(key, m, s, level):
    """Point ``s`` of ``m`` in the unit square for the reflected rays of the shaded ray of
    ``key`` at bounce ``level``: the R2 point (the pixel's anti-aliasing sample, then s)
    turned by the pixel's hash (streams of their own per bounce)."""
    pixel = key // KEY_STRIDE
    i = (key - pixel * KEY_STRIDE) * m + s
    return ((0.5 + i * R2_A1 + hash01(pixel, 5 + 2 * level)) % 1.0,
            (0.5 + i * R2_A2 + hash01(pixel, 6 + 2 * level)) % 1.0)


@leaf_njit
def ggx_sample(vx, vy, vz, fx, fy, fz, alpha, u1, u2):
    """A microfacet normal h of GGX (``alpha``) about the unit normal f drawn from the
    distribution of normals visible from the unit v (Heitz 2018) at (u1, u2)."""
    # an orthonormal basis (b1, b2, f) (Duff et al. 2017)
    sign = 1.0 if fz >= 0.0 else -1.0
    a = -1.0 / (sign + fz)
    b = fx * fy * a
    b1x, b1y, b1z = 1.0 + sign * fx * fx * a, sign * b, -sign * fx
    b2x, b2y, b2z = b, sign + fy * fy * a, -fy
    # v in that frame, stretched to the hemisphere of alpha 1
    x = alpha * (vx * b1x + vy * b1y + vz * b1z)
    y = alpha * (vx * b2x + vy * b2y + vz * b2z)
    z = vx * fx + vy * fy + vz * fz
    ln = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / ln, y / ln, z / ln
    lsq = x * x + y * y
    if lsq > 0.0:
        inv = 1.0 / math.sqrt(lsq)
        t1x, t1y, t1z = -y * inv, x * inv, 0.0
    else:
        t1x, t1y, t1z = 1.0, 0.0, 0.0
    t2x, t2y, t2z = y * t1z - z * t1y, z * t1x - x * t1z, x * t1y - y * t1x
    # a point of the projected hemisphere's disc
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    p1, p2 = r * math.cos(phi), r * math.sin(phi)
    sw = 0.5 * (1.0 + z)
    p2 = (1.0 - sw) * math.sqrt(max(1.0 - p1 * p1, 0.0)) + sw * p2
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    hx = p1 * t1x + p2 * t2x + p3 * x
    hy = p1 * t1y + p2 * t2y + p3 * y
    hz = p1 * t1z + p2 * t2z + p3 * z
    # unstretched, back in world space
    hx, hy, hz = alpha * hx, alpha * hy, max(hz, 0.0)
    ln = math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx / ln, hy / ln, hz / ln
    return (hx * b1x + hy * b2x + hz * fx, hx * b1y + hy * b2y + hz * fy,
            hx * b1z + hy * b2z + hz * fz)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _lobe_rays(v, f, f0, alpha, key, m, first, level, dirs, w):
    """The reflected rays of point i (view ``v`` towards the viewer, normal ``f``): rays
    ``first[i]`` .. ``first[i] + m[i]``: their unit directions into ``dirs`` and their
    weights into ``w`` (the mirror's F(n.v), a sample's F(v.h) G2 / G1(v) / m; 0 for a
    sample below the horizon)."""
    for i in range(len(v)):
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        fx, fy, fz = f[i, 0], f[i, 1], f[i, 2]
        cv = fx * vx + fy * vy + fz * vz
        a2 = alpha[i] * alpha[i]
        for s in range(m[i]):
            j = first[i] + s
            if alpha[i] > 0.0:
                u1, u2 = lobe_point(key[i], m[i], s, level)
                hx, hy, hz = ggx_sample(vx, vy, vz, fx, fy, fz, alpha[i], u1, u2)
            else:
                hx, hy, hz = fx, fy, fz
            vh = vx * hx + vy * hy + vz * hz
            dirs[j, 0] = 2.0 * vh * hx - vx
            dirs[j, 1] = 2.0 * vh * hy - vy
            dirs[j, 2] = 2.0 * vh * hz - vz
            cl = fx * dirs[j, 0] + fy * dirs[j, 1] + fz * dirs[j, 2]
            g = 1.0
            if alpha[i] > 0.0:
                lv = smith_lambda(cv, a2)
                g = (1.0 + lv) / (1.0 + lv + smith_lambda(cl, a2)) if cl > 0.0 else 0.0
            if not (cl > 0.0 and vh > 0.0):
                g = 0.0
            for c in range(3):
                w[j, c] = schlick(f0[i, c], vh) * g / m[i]
