"""What a render compiles: the warm-up compiles the kernels a render uses (trace,
secondary rays, the picture), other schemes' trace kernels compile in a helper, and the
shading of Catmull-Clark cages compiles no Loop normals."""

from __future__ import annotations

import pytest
from shared_data import COMPILE_LISTENER, MODELS, run_fresh


def test_warmup_compiles_the_kernels_a_render_uses():
    """On a cold cache a second process compiles the trace and shade kernels from empty
    inputs (``subtrace.startup.warmup``); that only helps if it does compile (or load) them, with
    exactly the types of a render: in a fresh process, the warm-up alone gives each kernel
    one specialisation, and a render after it adds none."""
    import subprocess
    import sys

    from subtrace.runtime import threads as tasks
    from subtrace.startup import warmup

    code = f"""
from subtrace import shade
from subtrace.runtime import threads as tasks
from subtrace.startup import warmup
from subtrace.trace import kernels
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
warmup.compile_kernels({tasks.max_threads()}, ["catmark"])
sigs = lambda: (len(kernels._trace_task.signatures), len(shade._shade_task.signatures))
before = sigs()
scene = scene_from_dict({{"object": [{{"mesh": {str(MODELS / "spot_control_mesh.obj")!r}}}],
    "camera": {{"eye": [1.2, 0.6, 2.2], "target": [0.0, 0.3, 0.0], "width": 32,
                "height": 24}}}})
assert render_scene(scene).stats.pixels_covered > 20
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert "".join(out) == "(1,1)(1,1)", out
    assert warmup.start(tasks.max_threads()) is None  # cached now: no second process


def test_the_secondary_ray_kernels_compile_with_the_types_of_a_render():
    """On a cold cache the secondary-ray kernel compiles while the trace kernels compile
    elsewhere (``trace.rays.compile_kernel`` on empty pools); that only helps if the types
    are those of a render: in a fresh process on two threads, it gives the kernel one
    specialisation and a render with shadows and anti-aliasing rays adds none."""
    import subprocess
    import sys

    code = f"""
from subtrace.runtime import threads as tasks
from subtrace.trace import rays
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
tasks.set_threads(2)
rays.compile_kernel()
tasks.set_threads(None)
sigs = lambda: len(rays._rays_task.signatures)
before = sigs()
scene = scene_from_dict({{"object": [{{"mesh": {str(MODELS / "spot_control_mesh.obj")!r}}}],
    "camera": {{"eye": [1.2, 0.6, 2.2], "target": [0.0, 0.3, 0.0], "width": 32,
                "height": 24}}, "render": {{"samples": 4}},
    "light": [{{"direction": [-1.0, -2.0, -0.5]}}]}})
stats = render_scene(scene, threads=2).stats
assert stats.pixels_covered > 20 and stats.shadow_rays > 0, stats
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["1", "1"], out


def test_warmup_compiles_the_picture_kernels_a_render_uses():
    """The helper compiles the picture's kernels (lights, background, ground with shadow rays,
    anti-aliasing flags: ``warmup.compile_picture``) from a few pixels; that only helps if
    their types are a render's: in a fresh process, a render with a light, shadows, a
    shadow-catching ground and anti-aliasing adds no signature to any of them."""
    import subprocess
    import sys

    code = f"""
from subtrace import shade
from subtrace.startup import warmup
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
warmup.compile_picture(2)
kernels = (shade._light_task, shade._background_task, shade._ground_first, shade._ground_rays,
           shade._ground_last, shade._hit_points_task, shade._shadow_count,
           shade._shadow_make, shade._shadow_mark, shade._luminance_rows, shade._pair_rows,
           shade._flag_rows)
sigs = lambda: [len(k.signatures) for k in kernels]
before = sigs()
scene = scene_from_dict({{"object": [{{"mesh": {str(MODELS / "spot_control_mesh.obj")!r}}}],
    "camera": {{"eye": [1.2, 0.6, 2.2], "target": [0.0, 0.3, 0.0], "width": 48,
                "height": 36}},
    "render": {{"samples": 4, "background": [[0.4, 0.4, 0.5], [0.1, 0.1, 0.1]]}},
    "light": [{{"direction": [-0.4, -1.0, -0.5]}}], "ground": {{}}}})
stats = render_scene(scene, threads=2).stats
assert stats.shadow_rays > 0 and stats.aa_pixels > 0, stats
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == " ".join([str([1] * 12)] * 2), out


def test_a_render_of_other_schemes_compiles_their_trace_kernel_in_a_helper(monkeypatch):
    """The trace kernel has a variant without the Loop descents (``bezier.loop_flag``): a
    render whose cages' variant the cache lacks starts a helper for it (told the schemes at
    once), one whose variant is cached starts none; the cache's index is read for it."""
    from subtrace.runtime import threads as tasks
    from subtrace.startup import warmup

    warmup.compile_kernels(tasks.max_threads(), ["catmark"])  # (loaded if cached)
    assert warmup._trace_variant_cached(None)
    monkeypatch.setattr(warmup, "_trace_variant_cached", lambda loop: loop is None)
    assert warmup.start_for(tasks.max_threads(), ["catmark", "catmark"]) is None
    helpers = warmup.start_for(tasks.max_threads(), ["catmark", "loop"])
    assert helpers is not None and len(helpers.procs) >= 1
    warmup.wait(helpers)
    assert all(proc.returncode == 0 for proc in helpers.procs)
    monkeypatch.undo()
    assert warmup._trace_variant_cached(True)  # what the helper compiled (or found)


def test_the_picture_kernels_compile_here_only_while_the_trace_kernel_is_not_ready(monkeypatch):
    """warmup.traced tells, without reading it, whether a helper has said "traced" (or
    ended); warmup.picture_while_tracing compiles the picture's groups other than the
    ground's one at a time until then, and none once it is."""
    import select
    import subprocess
    import sys

    from subtrace.startup import warmup

    said = "import sys, time; time.sleep({}); print('traced', flush=True); sys.stdin.read()"
    compiled = []
    monkeypatch.setattr(warmup, "compile_picture",
                        lambda threads, parts: compiled.append(parts))
    slow = subprocess.Popen([sys.executable, "-c", said.format(60)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)
    try:
        helpers = warmup.Helpers([slow], False)
        assert not warmup.traced(helpers)
        warmup.picture_while_tracing(helpers, 2)
        assert compiled == [(part,) for part in warmup.PICTURE if part != "ground"]
    finally:
        slow.kill()
        slow.wait()
    quick = subprocess.Popen([sys.executable, "-c", said.format(0)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE)
    helpers = warmup.Helpers([quick], False)
    assert select.select([quick.stdout], [], [], 60)[0]  # (it has said it)
    assert warmup.traced(helpers) and warmup.traced(helpers)  # (nothing read)
    compiled.clear()
    warmup.picture_while_tracing(helpers, 2)
    assert compiled == []
    warmup.wait_traced(helpers)
    warmup.wait(helpers)
    assert quick.returncode == 0 and warmup.traced(warmup.Helpers([], False))


_SHADING_PROBE = COMPILE_LISTENER + """
import json, sys
from subtrace.startup import warmup
warmup.compile_shading(1, None if sys.argv[1] == "catmark" else True)
print(json.dumps(compiled))
"""


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_the_shading_of_catmull_clark_cages_compiles_no_loop_normals(tmp_path, scheme):
    """shade.shade: the normals of hits on Loop items are a pass of their own, so the
    shading of Catmull-Clark cages (``loop`` None), in a fresh process on an empty cache,
    compiles neither that pass nor the Loop nets' normal; with Loop cages it compiles both
    (the golden Loop scenes check their numbers)."""
    import json

    compiled = json.loads(run_fresh(_SHADING_PROBE, scheme, cache=tmp_path / "cache"))
    names = {c.rpartition(".")[2] for c in compiled}
    assert "_shade_task" in names, compiled
    loop = {"_loop_normals_task", "tri_normal"} & names
    assert loop == (set() if scheme == "catmark" else {"_loop_normals_task", "tri_normal"})


def test_the_texture_kernels_compile_with_the_types_of_a_render():
    """The picture's warm-up compiles the image textures' kernels (the hits' tangents, the
    linear mode's UVs, the footprints, the MIP-map filter) on no hits and a one-texel
    texture (``warmup.compile_picture``'s "textures"): in a fresh process it gives each
    one specialisation, and a render of the textured default scene adds none."""
    import subprocess
    import sys

    code = """
from subtrace import textures
from subtrace.startup import warmup
from subtrace.data import default_scene_path
from subtrace.io.scene import apply_overrides, load_scene
from subtrace.render import render_scene
warmup.compile_picture(2, ["textures"])
ks = (textures._tangents_task, textures._linear_uv_task, textures._footprint_task,
      textures._lookup_task)
sigs = lambda: tuple(len(k.signatures) for k in ks)
before = sigs()
scene = apply_overrides(load_scene(default_scene_path()), width=48, height=27, samples=1)
assert render_scene(scene).stats.pixels_covered > 50
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert "".join(out) == "(1,1,1,1)(1,1,1,1)", out
