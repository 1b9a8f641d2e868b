"""numba's on-disk cache cannot hold a stale kernel: it is keyed on every kernel source.

numba invalidates a cached kernel only when the kernel's own file changes, yet a kernel
holds its callees (and the constants it reads) compiled inside it. tanbench therefore
puts the cache in a directory named by a hash of every source that jitted code can
reach (tanbench/kernel_cache.py). Here a temporary copy of the package compiles a kernel
of filters/resample.py, then a callee in another module (filters/vecmath.py) is edited:
the same caller must give the edited callee's numbers at once, from a new cache
directory under the user's NUMBA_CACHE_DIR.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

from sweep_support import ROOT, cli_env

# a caller in filters/resample.py whose callee (exp_nonpositive) lives in filters/vecmath.py
PROBE = """
import json
import numpy as np
import tanbench
from tanbench.filters.resample import exp_weights

w = np.empty(3)
exp_weights(np.array([-1.0, -2.0, -3.0]), 0.0, w)
print(json.dumps({"w": w.tolist(), "package": tanbench.__file__}))
"""
CALLEE_LINE = "    return 0.0 if low else out\n"


def probe(package_root, cache_parent) -> dict:
    env = cli_env()
    env["PYTHONPATH"] = str(package_root)
    env["NUMBA_CACHE_DIR"] = str(cache_parent)
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env,
                          cwd=package_root, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.splitlines()[-1])


def cache_dirs(parent) -> list[str]:
    return sorted(p.name for p in parent.iterdir()) if parent.is_dir() else []


def test_an_edited_callee_in_another_module_recompiles_its_caller(tmp_path):
    copy = tmp_path / "pkg"
    shutil.copytree(ROOT / "tanbench", copy / "tanbench", ignore=shutil.ignore_patterns("__pycache__"))
    parent = tmp_path / "numba cache"  # the user's NUMBA_CACHE_DIR, a space in its name
    first = probe(copy, parent)
    assert first["package"].startswith(str(copy))  # the copy runs, not the project's tree
    assert probe(copy, parent) == first  # from the cache

    vecmath = copy / "tanbench" / "filters" / "vecmath.py"
    text = vecmath.read_text()
    assert text.count(CALLEE_LINE) == 1
    vecmath.write_text(text.replace(CALLEE_LINE, "    return 0.0 if low else 2.0 * out\n"))
    edited = probe(copy, parent)
    assert edited["w"] == [2.0 * v for v in first["w"]]  # the callee's edit reached the cached caller
    # one cache directory per version of the kernel sources, under the user's NUMBA_CACHE_DIR
    names = cache_dirs(parent)
    assert len(names) == 2 and all(n.startswith("tanbench-kernels-") for n in names), names
