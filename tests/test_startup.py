"""The command's short-process start-up (runtime.jit.trim_loader): cached kernels load without
Numba's full target set-up, kernels that must compile still compile, and the image does
not change. Each case runs in a fresh interpreter, since the shortcut is process-wide."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import subtrace
from subtrace.io.exr import read_exr

# the subtrace this process imported (installed or the sources): the fresh processes must
# share its Numba cache, which is keyed on those files
SRC = Path(subtrace.__file__).resolve().parents[1]


def _python(code: str, **env_extra) -> str:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(env_extra)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_a_warm_command_renders_the_same_image_without_the_full_target_setup(tmp_path):
    """The launcher path (own process) against an in-process render of the same scene:
    every channel equal; once the kernels are cached, Numba's target set-up never ran
    (numba.np.npyimpl is a module only that set-up imports) and scipy.linalg was never
    imported."""
    from subtrace.cli import main

    inproc = tmp_path / "inproc.exr"
    argv = ["render", "--width", "48", "--height", "32", "--quiet"]
    assert main([*argv, "-o", str(inproc)]) == 0  # also leaves every kernel cached
    own = tmp_path / "own.exr"
    code = f"""
import sys
from subtrace.cli import main
code = main({[*argv, "-o", str(own)]!r}, own_process=True)
print(code, "numba.np.npyimpl" in sys.modules, "scipy.linalg" in sys.modules)
"""
    assert _python(code).split() == ["0", "False", "False"]
    a, _ = read_exr(inproc)
    b, _ = read_exr(own)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_a_kernel_that_is_not_cached_still_compiles_without_scipy_linalg(tmp_path):
    """After the shortcut, a kernel missing from the cache goes through Numba's compiler,
    which sets the whole target up itself (here: array maths and a reduction need the
    numpy registries), still refusing the scipy.linalg import during the set-up."""
    code = """
import sys
import argparse
import numpy as np
import numba
from subtrace.runtime.jit import trim_loader
trim_loader()

@numba.njit
def f(a):
    return np.sum(np.sqrt(a) * 2.0)

print(f(np.array([1.0, 4.0, 9.0])), "scipy.linalg" in sys.modules)
"""
    out = _python(code, NUMBA_CACHE_DIR=str(tmp_path / "cold")).split()
    assert out == ["12.0", "False"]


def test_the_warm_up_looks_for_the_index_files_numba_writes():
    """startup.warmup._index_files looks in the folder, and for the names, where Numba's
    cache keeps each warm-up kernel's index (so a warm cache is recognised and no helper
    process starts)."""
    import fnmatch

    from subtrace.startup import warmup
    from subtrace.shade import _shade_task
    from subtrace.trace.kernels import _trace_task
    from subtrace.trace.rays import _rays_task

    kernels = {"_trace_task": _trace_task, "_shade_task": _shade_task, "_rays_task": _rays_task}
    assert set(kernels) == set(warmup._KERNEL_MODULES)
    for name, kernel in kernels.items():
        index = Path(kernel._cache._cache_file._index_path)
        folder, pattern = warmup._index_pattern(name)
        assert index.parent == folder and fnmatch.fnmatch(index.name, pattern), (name, index)
