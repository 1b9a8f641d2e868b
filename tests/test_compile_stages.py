"""The kernels side-by-side compile processes share, split between them (tanbench.runner.compile_stages)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numba.core import types

from tanbench.config import Scenario
from tanbench.runner import compile_stages as stages
from tanbench.terrain.grid import NodeGrid

GROUPS = [["loose-dvl"], ["tight-dvl", "tight-sbe"]]


def test_argument_types_survive_their_json_form():
    """Every kind of argument type the kernels take comes back equal from its JSON form (read-only and
    layout included: they are part of a signature)."""
    import numba

    grid = numba.typeof(NodeGrid(np.zeros(4), 1, 0.0, 0.0, 1.0, 1.0, 2, 2))
    kinds = [types.Array(types.float64, 2, "C"), types.Array(types.float64, 1, "C", readonly=True),
             types.Array(types.int32, 2, "A"), types.Array(types.uint64, 1, "C"), types.int64, types.float64,
             types.boolean, types.UniTuple(types.float64, 9), types.Tuple((types.int64, types.float64)), grid,
             types.Omitted(0.0), types.literal(5), types.literal(True)]
    for ty in kinds:
        again = stages.decode_type(json.loads(json.dumps(stages.encode_type(ty))))
        assert again == ty, ty
    with pytest.raises(TypeError, match="no JSON form"):
        stages.encode_type(types.unicode_type)


def test_the_committed_table_resolves_to_this_codes_kernels():
    """Each entry names a jitted kernel of the package and decodes its argument types, and each family's
    share is the families' recorded shared roots: no kernel in two shares."""
    from numba.core.registry import CPUDispatcher

    table = stages.load_table()
    assert set(table["shares"]) == set(stages.RECORDED) == {"tight", "loose"}
    names = [e["kernel"] for share in table["shares"].values() for e in share]
    assert names and len(names) == len({(e["kernel"], json.dumps(e["signature"]))
                                        for share in table["shares"].values() for e in share})
    for share in table["shares"].values():
        for entry in share:
            module, qualname = entry["kernel"].rsplit(".", 1)
            assert isinstance(stages._resolve(module, qualname), CPUDispatcher), entry["kernel"]
            assert all(stages.decode_type(t) is not None for t in entry["signature"])


def test_a_share_skips_what_does_not_resolve():
    """A renamed kernel, a type this numba cannot build, or types the kernel does not compile for (the
    third entry: one integer where it takes four arguments) are skipped, not an error."""
    bogus = [{"kernel": "tanbench.filters.resample.no_such_kernel", "signature": [["scalar", "int64"]]},
             {"kernel": "tanbench.filters.resample.resample_indices", "signature": [["nonsense"]]},
             {"kernel": "tanbench.filters.resample.resample_indices", "signature": [["scalar", "int64"]]}]
    assert stages.compile_share(bogus) == (0, ["tanbench.filters.resample.no_such_kernel",
                                               "tanbench.filters.resample.resample_indices",
                                               "tanbench.filters.resample.resample_indices"])
    assert stages.compile_share([]) == (0, [])


def test_shares_go_to_the_groups_of_their_families_and_only_for_the_default_variant():
    table = stages.load_table()["shares"]
    assert stages.shares_for(GROUPS, Scenario()) == [table["loose"], table["tight"]]
    assert stages.shares_for(GROUPS[::-1], Scenario()) == [table["tight"], table["loose"]]
    assert stages.shares_for([["tight-dvl", "pmf-dvl"], ["loose-dvl"]], Scenario()) == [table["tight"], table["loose"]]
    assert stages.shares_for([["tight-dvl", "loose-dvl"]], Scenario()) == [[]]  # one process: nothing to share
    assert stages.shares_for([["tight-dvl"], ["pmf-dvl"]], Scenario()) == [[], []]  # loose not compiling
    numpy_rng = Scenario(filter={"random_numbers": "numpy"})  # other argument types than the table's
    assert stages.shares_for(GROUPS, numpy_rng) == [[], []]


def test_the_split_shares_the_roots_and_balances_the_processes():
    """Kernels both families compile with the same types are shared; those a shared kernel calls are
    compiled inside it, so only the roots are listed, the longest first to the family that is then shortest."""
    def comp(kernel, seconds, caller=None, sig=(("scalar", "int64"),)):
        return {"kernel": kernel, "signature": [list(s) for s in sig], "seconds": seconds, "caller": caller}

    records = {
        "a": {"seconds": 30.0, "compiles": [comp("t.leaf", 1.0, "t.big"), comp("t.big", 8.0, "t.loop_a"),
                                            comp("t.mid", 3.0), comp("t.small", 1.0), comp("t.loop_a", 20.0),
                                            comp("t.other_types", 2.0, sig=(("scalar", "float64"),))]},
        "b": {"seconds": 20.0, "compiles": [comp("t.leaf", 1.0, "t.big"), comp("t.big", 7.0), comp("t.mid", 2.0),
                                            comp("t.small", 1.5, "t.loop_b"), comp("t.loop_b", 9.0),
                                            comp("t.other_types", 2.0)]},
    }
    table = stages.split_shares(records)
    shared = {e["kernel"]: fam for fam, share in table["shares"].items() for e in share}
    assert set(shared) == {"t.big", "t.mid", "t.small"}  # t.leaf runs inside t.big; t.other_types differs
    # own seconds: a 30 - (8 + 3 + 1) = 18, b 20 - (7 + 2 + 1.5) = 9.5; each root at its longer time:
    # big (8) to b (17.5), mid (3) to b (20.5), small (1.5) to a (19.5)
    assert table["own_seconds"] == {"a": 18.0, "b": 9.5}
    assert shared == {"t.big": "b", "t.mid": "b", "t.small": "a"}
    assert table["expected_seconds"] == {"a": 19.5, "b": 20.5}


def test_the_table_is_written_one_kernel_a_line_and_reads_back_equal(tmp_path):
    table = stages.load_table()
    path = tmp_path / "stages.json"
    stages.write_table(table, path)
    assert json.loads(path.read_text()) == table
    kernels = sum(len(share) for share in table["shares"].values())
    assert sum('"kernel":' in line for line in path.read_text().splitlines()) == kernels
