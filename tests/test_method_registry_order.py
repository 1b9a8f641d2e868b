"""The built-in methods are listed in one fixed order (by seed id), whatever order their modules were
imported in: tests take a method's filter seed from its index in that list (docs/speed.md, "Method order
and the tests' seeds")."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import importlib, sys
for module in sys.argv[1:]:
    importlib.import_module(module)
from tanbench.methods.registry import builtin_names, names
print(",".join(builtin_names())); print(",".join(names()))
"""


def _listed_after_importing(*modules: str) -> str:
    return subprocess.run([sys.executable, "-c", SCRIPT, *modules], capture_output=True, text=True,
                          check=True).stdout


def test_builtin_order_does_not_depend_on_import_order():
    plain = _listed_after_importing()
    assert _listed_after_importing("tanbench.methods.mpf") == plain
    assert _listed_after_importing("tanbench.methods.multibeam", "tanbench.methods.pmf") == plain


def test_builtins_are_listed_by_seed_id():
    from tanbench.methods.registry import builtin_names, get

    ids = [get(n).seed_id for n in builtin_names()]
    assert ids == sorted(ids) and builtin_names()[:3] == ("tight-dvl", "tight-sbe", "loose-dvl")
