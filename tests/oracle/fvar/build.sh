#!/bin/sh
# Builds generate.cpp against the system's OpenSubdiv (Debian: apt install libosd-dev) and
# writes one .npz per shape beside this script (see README.md). Run from anywhere:
#     tests/oracle/fvar/build.sh            (PYTHON: a Python with NumPy, default python3)
set -eu
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../../.." && pwd)
python=${PYTHON:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
${CXX:-g++} -O2 -std=c++14 -o "$work/generate" "$here/generate.cpp" -losdCPU

# shape, scheme, stride over the ptex faces for corner / centre / side samples, levels
while read -r obj scheme stride levels; do
    name=$(basename "$obj" .obj)
    mkdir "$work/$name"
    "$work/generate" "$repo/$obj" "$scheme" "$work/$name" "$stride" "$levels"
    "$python" - "$work/$name" "$here/$name.npz" <<'EOF'
import json, sys
from pathlib import Path
import numpy as np
src, dst = Path(sys.argv[1]), sys.argv[2]
arrays = {p.stem: np.load(p) for p in sorted(src.glob("*.npy"))}
arrays["meta"] = np.array(json.dumps(json.loads((src / "meta.json").read_text())))
np.savez_compressed(dst, **arrays)
EOF
    echo "$name.npz"
done <<'LIST'
tests/oracle/shapes/catmark_fvar_bound0.obj catmark 1 2
tests/oracle/shapes/catmark_fvar_bound3.obj catmark 1 2
tests/oracle/shapes/loop_fvar_bound0.obj loop 1 2
tests/oracle/fvar/shapes/catmark_fvar_seams.obj catmark 1 2
tests/oracle/fvar/shapes/catmark_fvar_chaikin.obj catmark 2 2
tests/oracle/fvar/shapes/loop_fvar_seams.obj loop 2 2
tests/oracle/shapes/catmark_val2_interior.obj catmark 2 1
tests/oracle/shapes/catmark_nonman_edges.obj catmark 4 1
tests/oracle/shapes/catmark_smoothtris1.obj catmark 8 1
tests/oracle/shapes/catmark_hole_test3.obj catmark 2 1
tests/oracle/shapes/catmark_edgenone.obj catmark 2 1
tests/oracle/shapes/loop_cubes_semisharp.obj loop 4 1
models/spot_control_mesh.obj catmark 3 1
LIST
