"""pytest set-up of subtrace's tests.

The tests leave the machine as they found it. Before subtrace is imported, this file points
everything the tests (and the processes they start, which inherit the environment) would
write at one temporary folder for the whole run, removed when the run ends:

* the kernel cache (``SUBTRACE_CACHE_DIR`` and ``NUMBA_CACHE_DIR``): one cache for the run,
  so each kernel compiles once however many tests use it, and never ``~/.cache/subtrace``
  or ``$XDG_CACHE_HOME/subtrace``. A ``SUBTRACE_CACHE_DIR`` of the user's is not used either:
  the suite must pass on an empty cache and must not fill one it was not given. A developer
  who reruns tests often names a cache folder for the tests in ``SUBTRACE_TEST_CACHE_DIR``
  (created if need be, kept afterwards); tests that check the cache itself use folders of
  their own;
* Python's bytecode (``PYTHONPYCACHEPREFIX``), Hypothesis's example database
  (``HYPOTHESIS_STORAGE_DIRECTORY``) and Matplotlib's font cache (``MPLCONFIGDIR``), so
  nothing is written into the checkout (``pytest -p no:cacheprovider`` in pyproject.toml:
  no ``.pytest_cache``; ``-p cacheprovider`` turns it back on for ``--lf``).

The golden images (``golden_images/<scene>.exr``) are compared by subtrace's own pytest
plugin (:mod:`subtrace.testing.plugin`, the ``golden`` fixture; ``--update-goldens`` rewrites
them from fresh renders), which pytest loads from its entry point before this file. Its
session page (``report.html``, with the images of any golden that failed) goes to
``GOLDEN_REPORT`` in the system's temporary folder, kept after the run for a look and
replaced by the next one, unless ``--golden-report DIR`` names another: not the checkout.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

# pytest loads subtrace's plugin (subtrace.testing.plugin) before this file: it imports the
# package and itself only, which read no environment variable; nothing else of subtrace's may
# be loaded yet (the kernel cache folder is read when the kernels load)
PLUGIN_MODULES = {"subtrace", "subtrace.version", "subtrace.testing", "subtrace.testing.plugin"}
_loaded = {m for m in sys.modules if m == "subtrace" or m.startswith("subtrace.")}
assert _loaded <= PLUGIN_MODULES, f"conftest.py must run before {sorted(_loaded - PLUGIN_MODULES)}"

RUN_DIR = Path(tempfile.mkdtemp(prefix="subtrace-tests-"))
GOLDEN_REPORT = Path(tempfile.gettempdir()) / f"subtrace-golden-report-{os.getuid()}"
KERNEL_CACHE = Path(os.environ.get("SUBTRACE_TEST_CACHE_DIR") or RUN_DIR / "kernels")


def _private_folders() -> None:
    """Point the caches and databases of this process and its children at RUN_DIR."""
    KERNEL_CACHE.mkdir(parents=True, exist_ok=True)
    os.environ["SUBTRACE_CACHE_DIR"] = os.environ["NUMBA_CACHE_DIR"] = str(KERNEL_CACHE)
    os.environ["PYTHONPYCACHEPREFIX"] = sys.pycache_prefix = str(RUN_DIR / "bytecode")
    os.environ["HYPOTHESIS_STORAGE_DIRECTORY"] = str(RUN_DIR / "hypothesis")
    os.environ["MPLCONFIGDIR"] = str(RUN_DIR / "matplotlib")
    from hypothesis.configuration import set_hypothesis_home_dir

    set_hypothesis_home_dir(RUN_DIR / "hypothesis")  # (in case its plugin read it already)


_private_folders()

# pytester runs the sample project of tests/golden_project (tests/test_golden_plugin.py)
pytest_plugins = ["pytester"]


def pytest_configure(config):
    if config.getoption("golden_report", None) is None:
        config.option.golden_report = str(GOLDEN_REPORT)


def pytest_unconfigure(config):
    shutil.rmtree(RUN_DIR, ignore_errors=True)
    # pytest wrote this file's own bytecode beside it before the lines above could say
    # otherwise: removed, with its folder when nothing else is in it
    here = Path(__file__).parent / "__pycache__"
    for pyc in here.glob(f"conftest.{sys.implementation.cache_tag}*.pyc"):
        pyc.unlink(missing_ok=True)
    try:
        here.rmdir()
    except OSError:  # absent, or holds other files
        pass
