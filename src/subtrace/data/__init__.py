"""Sample data shipped inside the package.

``spot_control_mesh.obj``: the Catmull-Clark control cage of "Spot" by Keenan Crane
(Keenan's 3D Model Repository, https://www.cs.cmu.edu/~kmcrane/Projects/ModelRepository/),
released into the public domain; copied unchanged. 188 vertices, 180 faces (160 quads,
16 pentagons, 4 triangles), closed, genus 0. ``subtrace info`` uses it when no cage is given.

``spot_texture.png``: Spot's texture by Keenan Crane (same repository, public domain), a
1024x1024 PNG rasterised once from its vector original (``models/spot_texture.png``, whose
``models/README.md`` entry says how); the default scene's diffuse texture.

``plate_holes.obj``: a trimmed bicubic B-spline plate with two holes (rational and Bezier
trimming curves), a copy of ``models/nurbs/plate_holes.obj``: ``subtrace warmup`` renders
and intersects it to compile the NURBS kernels.
"""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent


def sample_cage_path() -> Path:
    """Path of the built-in sample cage (Spot, Catmull-Clark, public domain)."""
    return _HERE / "spot_control_mesh.obj"


def default_scene_path() -> Path:
    """Path of the built-in default scene of ``subtrace render`` (Spot, 1280x720, 1 px)."""
    return _HERE / "default_scene.toml"


def sample_surfaces_path() -> Path:
    """Path of the built-in trimmed NURBS sample (a plate with two holes)."""
    return _HERE / "plate_holes.obj"
