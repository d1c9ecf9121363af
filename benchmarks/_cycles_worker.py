"""Blender side of ``benchmarks/cycles.py``: build one scene in Cycles and render it once.

    BPY_PYTHON _cycles_worker.py JOB.json RESULT.json

Runs under the Python of the virtual environment that holds the ``bpy`` wheel (never under
subtrace's). JOB.json (written by ``cycles.py``) holds the cages as plain lists (positions,
faces, edge creases and vertex creases already in Blender's 0..1 units), the boundary mode,
the camera, the lights and the output paths. RESULT.json receives:

    blender        Blender's version string
    time_build     s: factory reset, mesh, modifier, camera, lights, render settings
    time_render    s: ``bpy.ops.render.render()`` alone (Cycles' own render time)
    time_sync      s: from that call to Cycles' first "Sample" status: scene sync, adaptive
                   tessellation (dicing), BVH build, device upload
    time_tessellate, time_bvh   s: the parts of time_sync spent in the "Tessellating" and
                   "Building BVH" statuses (status time stamps; indicative)
    time_samples   s: time_render - time_sync: path tracing the one sample, film read-back
    time_write     s: writing the EXR / PNG (not part of time_render)
    cycles_mem_mb  Cycles' own peak memory figure from its status line ("Mem: ...M")

The camera follows subtrace's: forward = target - eye, right = forward x up, true up =
right x forward; Blender's camera looks down its local -Z with +Y up, so its world matrix has
the columns right, true up, -forward and the eye. ``fov`` is the vertical field of view.
"""

import json
import math
import os
import re
import sys
import time


def _normalize(v):
    n = math.sqrt(sum(c * c for c in v))
    return [c / n for c in v]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _rotation_to(direction):
    """A 4x4 world matrix whose local -Z points along ``direction`` (for sun lights)."""
    from mathutils import Matrix, Vector

    d = Vector(_normalize(direction))
    return d.to_track_quat("-Z", "Y").to_matrix().to_4x4() if d.length else Matrix.Identity(4)


def _add_cage(scene, item, dicing_rate, k):
    """One cage as a mesh object with creases, an adaptive Subdivision Surface modifier and
    a diffuse material."""
    import bpy

    mesh = bpy.data.meshes.new(f"cage{k}")
    mesh.from_pydata(item["positions"], [], item["faces"])
    mesh.update()
    mesh.shade_smooth()
    if item["edge_creases"]:
        index = {}
        for e in mesh.edges:
            a, b = e.vertices
            index[(min(a, b), max(a, b))] = e.index
        values = [0.0] * len(mesh.edges)
        for a, b, c in item["edge_creases"]:
            i = index.get((min(a, b), max(a, b)))
            if i is not None:  # a tag on a pair that is not an edge: OpenSubdiv ignores it too
                values[i] = max(values[i], c)
        attr = mesh.attributes.new("crease_edge", "FLOAT", "EDGE")
        attr.data.foreach_set("value", values)
    if item["vertex_creases"]:
        values = [0.0] * len(mesh.vertices)
        for v, c in item["vertex_creases"]:
            values[v] = max(values[v], c)
        attr = mesh.attributes.new("crease_vert", "FLOAT", "POINT")
        attr.data.foreach_set("value", values)
    obj = bpy.data.objects.new(f"cage{k}", mesh)
    scene.collection.objects.link(obj)

    # adaptive subdivision: Catmull-Clark, limit surface, dicing rate in pixels
    mod = obj.modifiers.new("subdivision", "SUBSURF")
    mod.subdivision_type = "CATMULL_CLARK"
    mod.use_creases = True
    mod.use_limit_surface = True
    mod.boundary_smooth = item["boundary_smooth"]
    if hasattr(mod, "use_adaptive_subdivision"):  # Blender 5: a modifier option
        mod.use_adaptive_subdivision = True
        mod.adaptive_space = "PIXEL"
        mod.adaptive_pixel_size = dicing_rate
    else:  # Blender 4: Cycles' experimental feature set and per-object settings
        scene.cycles.feature_set = "EXPERIMENTAL"
        obj.cycles.use_adaptive_subdivision = True
        obj.cycles.dicing_rate = 1.0
    scene.cycles.dicing_rate = dicing_rate

    # material: diffuse, the scene object's colour
    mat = bpy.data.materials.new(f"diffuse{k}")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes.get("Principled BSDF")
    if bsdf is not None:
        mat.node_tree.nodes.remove(bsdf)
    diffuse = mat.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = list(item["color"]) + [1.0]
    out = mat.node_tree.nodes.get("Material Output")
    mat.node_tree.links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    mesh.materials.append(mat)


def build(job):
    import bpy
    from mathutils import Matrix

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"  # first: Cycles' settings (scene.cycles) come with it

    for k, item in enumerate(job["objects"]):
        _add_cage(scene, item, job["dicing_rate"], k)

    # camera
    cam = job["camera"]
    eye, target, up = cam["eye"], cam["target"], cam["up"]
    forward = _normalize([t - e for t, e in zip(target, eye)])
    right = _normalize(_cross(forward, up))
    true_up = _cross(right, forward)
    world = Matrix.Identity(4)
    for k in range(3):
        world[k][0], world[k][1], world[k][2], world[k][3] = (
            right[k], true_up[k], -forward[k], eye[k])
    distance = math.dist(eye, target)
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(cam["fov"])
    cam_data.clip_start = max(1e-6, 1e-3 * distance)
    cam_data.clip_end = 1e4 * distance
    cam_obj = bpy.data.objects.new("camera", cam_data)
    cam_obj.matrix_world = world
    scene.collection.objects.link(cam_obj)
    scene.camera = cam_obj

    # lights: subtrace's are Lambertian directional lights (radiance colour * intensity *
    # cos); a sun of strength pi * intensity on a diffuse surface gives the same, no shadows
    lights = list(job["lights"])
    if job["headlight"] > 0.0:
        lights.append({"direction": forward, "color": [1.0, 1.0, 1.0],
                       "intensity": job["headlight"]})
    for i, light in enumerate(lights):
        sun = bpy.data.lights.new(f"sun{i}", "SUN")
        sun.energy = math.pi * light["intensity"]
        sun.color = light["color"]
        sun.angle = 0.0
        if hasattr(sun, "use_shadow"):
            sun.use_shadow = False
        sun_obj = bpy.data.objects.new(f"sun{i}", sun)
        sun_obj.matrix_world = _rotation_to(light["direction"])
        scene.collection.objects.link(sun_obj)
    world_data = bpy.data.worlds.new("world")
    world_data.use_nodes = True
    world_data.node_tree.nodes["Background"].inputs["Color"].default_value = (
        list(job["background"]) + [1.0])
    world_data.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world_data

    # render settings: CPU, 1 sample, fixed threads, no denoising, direct light only
    render = scene.render
    render.resolution_x, render.resolution_y = cam["width"], cam["height"]
    render.resolution_percentage = 100
    render.pixel_aspect_x = render.pixel_aspect_y = 1.0
    render.threads_mode = "FIXED"
    render.threads = job["threads"]
    render.use_persistent_data = False
    render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = 1
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.max_bounces = 0
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    cycles.seed = 0
    return scene


def main():
    job_path, result_path = sys.argv[-2], sys.argv[-1]
    # this file's folder holds benchmarks/cycles.py, which would shadow Blender's "cycles"
    # add-on package: take the folder off the import path before bpy loads its add-ons
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != here]
    with open(job_path) as f:
        job = json.load(f)

    t0 = time.perf_counter()
    import bpy

    scene = build(job)
    t_build = time.perf_counter() - t0

    # status time stamps, to split the render into sync (dicing, BVH) and sampling
    stamps = []
    bpy.app.handlers.render_stats.append(lambda text: stamps.append((time.perf_counter(), text)))
    t_start = time.perf_counter()
    bpy.ops.render.render()
    t_end = time.perf_counter()

    def phase(word):
        """Seconds spent in statuses containing ``word`` (until the next status)."""
        total = 0.0
        for (t, text), (t_next, _) in zip(stamps, stamps[1:] + [(t_end, "")]):
            if word in text:
                total += t_next - t
        return total

    t_sample = next((t for t, text in stamps if re.search(r"\| Sample \d", text)), t_end)
    mems = [float(m) for _, text in stamps for m in re.findall(r"Mem:\s*([\d.]+)M", text)]

    t0 = time.perf_counter()
    image = bpy.data.images["Render Result"]
    if job.get("exr"):
        settings = scene.render.image_settings
        settings.file_format = "OPEN_EXR"
        settings.color_mode = "RGBA"
        settings.color_depth = "32"
        image.save_render(job["exr"], scene=scene)
    t_write = time.perf_counter() - t0

    result = {
        "blender": bpy.app.version_string,
        "time_build": t_build,
        "time_render": t_end - t_start,
        "time_sync": t_sample - t_start,
        "time_tessellate": phase("Tessellating"),
        "time_bvh": phase("Building BVH"),
        "time_samples": t_end - t_sample,
        "time_write": t_write,
        "cycles_mem_mb": max(mems) if mems else None,
    }
    with open(result_path, "w") as f:
        json.dump(result, f)


if __name__ == "__main__":
    main()
