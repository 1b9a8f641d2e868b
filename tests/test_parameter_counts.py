"""No driver or jitted loop with more than 12 parameters (issue 26).

Counted from the sources (``ast``) in the packages that carry settings to kernels:
tanbench/filters, tanbench/methods and tanbench/navigation. A loop with many settings takes
them as named-tuple bundles built from the spec beside the kernel (``filters/tight.py``
shows the pattern: ``TightTrack``, ``TightSettings``, ``TightOutputs``; the inner kernels take
the map as ``MapArgs`` or ``NodeGrid`` and small bundles such as ``BeamConstants``,
``SharedMotion``, ``LooseMotion``). No function is exempt.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "tanbench"
LIMIT = 12
PACKAGES = ("filters", "methods", "navigation")


def parameter_counts() -> dict[str, int]:
    """'package/module.py:function' -> number of parameters (positional, keyword-only, *args, **kwargs)."""
    out = {}
    for package in PACKAGES:
        for path in sorted((PACKAGE / package).glob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    a = node.args
                    count = (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
                             + (a.kwarg is not None))
                    out[f"{package}/{path.name}:{node.name}"] = max(count, out.get(f"{package}/{path.name}:{node.name}", 0))
    return out


def test_no_function_above_the_limit():
    over = {name: n for name, n in parameter_counts().items() if n > LIMIT}
    assert not over, f"functions with more than {LIMIT} parameters (bundle them): {over}"


def test_the_count_reads_the_kernels():
    """The count sees every package's functions, defaults, ``*args`` and keyword-only parameters."""
    counts = parameter_counts()
    assert counts["filters/tight.py:tight_filter_loop"] == 9  # the ninth: the global search, or None
    assert counts["filters/propagate.py:propagate_tight_euler"] == 12  # two with defaults
    assert counts["filters/likelihood.py:loglik_tight"] == LIMIT
    assert {name.split("/")[0] for name in counts} == set(PACKAGES)
