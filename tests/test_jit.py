"""Numba cache folders: one per source version, old ones pruned."""

from __future__ import annotations

import os

from subtrace.runtime import jit


def test_prune_keeps_the_most_recent_cache_folders(tmp_path):
    n = jit.CACHES_KEPT + 3
    for k in range(n):
        d = tmp_path / f"numba-{k:016x}"
        d.mkdir()
        (d / "index.nbi").write_bytes(b"x")
        os.utime(d, (1_000_000 + k, 1_000_000 + k))  # folder k used at time k
    (tmp_path / "other").mkdir()  # not a cache folder: left alone
    (tmp_path / "numba-notakey").mkdir()  # another program's folder in a shared base: kept
    os.utime(tmp_path / "numba-notakey", (0, 0))
    jit.prune_caches(tmp_path)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == [f"numba-{k:016x}" for k in range(3, n)] + ["numba-notakey", "other"]
