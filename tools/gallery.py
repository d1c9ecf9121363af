"""Render the gallery (README and docs/guide/gallery.md): a small PNG of every scene in ``scenes/`` and of the built-in
default scene, into ``docs/gallery/``.

    PYTHONPATH=src python tools/gallery.py [--width 384] [--height 216] [--out docs/gallery]

Each scene is rendered with its own camera, lights, ground and materials at the given size
(default 384x216, the scenes' 16:9), with the renderer's defaults (shadows, adaptive
anti-aliasing), as an opaque 8-bit sRGB PNG. Prints one line per picture: its name, the
render time and what it shows.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=384)
    ap.add_argument("--height", type=int, default=216)
    ap.add_argument("--out", default=str(REPO / "docs" / "gallery"))
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO / "src"))
    from subtrace.data import default_scene_path
    from subtrace.io.exr import write_picture
    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.render import render_scene

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scenes = [("default", Path(default_scene_path()))]
    scenes += [(p.stem, p) for p in sorted((REPO / "scenes").glob("*.toml"))]
    for name, path in scenes:
        scene = apply_overrides(load_scene(path), width=args.width, height=args.height)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (tags a scene's cage does not use)
            result = render_scene(scene)
        ch = result.channels
        write_picture(out / f"{name}.png", {c: ch[c] for c in "RGB"})
        st = result.stats
        print(f"{name}: {time.perf_counter() - t0:.2f} s, {st.pixels_covered} px covered, "
              f"{st.shadow_rays} shadow rays, {st.aa_pixels} anti-aliased px")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
