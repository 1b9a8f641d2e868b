"""The on-disk store of synthetic seafloors: the same map bit for bit, named by code and spec, never in the way."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from tanbench import kernel_cache
from tanbench.config import Scenario
from tanbench.terrain import _truth_cached, seafloor_cache, synthesise_seafloor, truth_map
from tanbench.terrain import terrain_key

SPEC = Scenario().terrain.model_copy(update={"seed": 3})  # a seafloor the session fixtures do not use


@pytest.fixture
def store_in(tmp_path, monkeypatch):
    """Seafloors stored under a fresh cache parent for this test."""
    monkeypatch.setattr(kernel_cache, "cache_parent", lambda: tmp_path)
    _truth_cached.cache_clear()
    yield tmp_path
    _truth_cached.cache_clear()


@lru_cache(maxsize=None)
def synthesised(spec):
    """The map synthesised here, without the store (once per spec in this module)."""
    return synthesise_seafloor(spec)


def assert_same_map(got, want):
    assert got.z.dtype == want.z.dtype and got.z.shape == want.z.shape
    assert got.z.tobytes() == want.z.tobytes()
    for name in ("e0", "n0", "res_e", "res_n", "name", "meta"):
        assert getattr(got, name) == getattr(want, name) and type(getattr(got, name)) is type(getattr(want, name))


def test_a_stored_seafloor_is_the_synthesised_one_bit_for_bit(store_in):
    first = truth_map(SPEC)
    stored = list(seafloor_cache.cache_dir().glob("*.npz"))
    assert len(stored) == 1 and seafloor_cache.cache_dir().parent == store_in
    _truth_cached.cache_clear()
    again = truth_map(SPEC)  # read from the disk this time
    assert again is not first
    assert_same_map(again, synthesised(SPEC))
    assert_same_map(first, synthesised(SPEC))


def test_the_directory_is_named_by_the_code_and_the_file_by_the_spec(store_in, monkeypatch):
    truth_map(SPEC)
    other_seed = SPEC.model_copy(update={"seed": 4})
    truth_map(other_seed)
    assert len(list(seafloor_cache.cache_dir().glob("*.npz"))) == 2
    before = seafloor_cache.cache_dir()
    # another version of the synthesis code (or numpy) reads nothing stored by this one and removes its directory
    monkeypatch.setattr(seafloor_cache, "sources_hash", lambda: "0" * 16)
    assert seafloor_cache.cache_dir() != before
    assert seafloor_cache.load(terrain_key(SPEC)) is None
    _truth_cached.cache_clear()
    assert_same_map(truth_map(SPEC), synthesised(SPEC))
    assert not before.exists()


def test_an_edit_to_a_terrain_source_changes_the_directory(tmp_path, monkeypatch):
    package = tmp_path / "tanbench"
    (package / "terrain").mkdir(parents=True)
    (package / "terrain" / "synthetic.py").write_text("x = 1\n")
    (package / "config.py").write_text("y = 1\n")
    monkeypatch.setattr(kernel_cache, "PACKAGE", package)
    seafloor_cache.sources_hash.cache_clear()
    try:
        first = seafloor_cache.sources_hash()
        (package / "terrain" / "synthetic.py").write_text("x = 2\n")
        seafloor_cache.sources_hash.cache_clear()
        assert seafloor_cache.sources_hash() != first
    finally:
        seafloor_cache.sources_hash.cache_clear()


def test_a_damaged_or_foreign_file_is_synthesised_again_and_replaced(store_in):
    truth_map(SPEC)
    (path,) = seafloor_cache.cache_dir().glob("*.npz")
    path.write_bytes(b"PK\x03\x04 half a file")
    _truth_cached.cache_clear()
    assert_same_map(truth_map(SPEC), synthesised(SPEC))
    assert seafloor_cache.load(terrain_key(SPEC)) is not None  # stored whole again
    # a file holding another spec under this name (a hash collision) is not taken for this one
    other = synthesised(SPEC.model_copy(update={"seed": 4}))
    seafloor_cache.store(terrain_key(SPEC.model_copy(update={"seed": 4})), other)
    (other_path,) = [p for p in seafloor_cache.cache_dir().glob("*.npz") if p != path]
    other_path.replace(path)
    assert seafloor_cache.load(terrain_key(SPEC)) is None


def test_an_unwritable_cache_only_costs_the_synthesis(tmp_path, monkeypatch):
    blocked = tmp_path / "file-not-a-directory"
    blocked.write_text("")
    monkeypatch.setattr(kernel_cache, "cache_parent", lambda: blocked)
    _truth_cached.cache_clear()
    try:
        assert_same_map(truth_map(SPEC), synthesised(SPEC))
        assert list(tmp_path.rglob("*.npz")) == [] and list(tmp_path.rglob("*.tmp*")) == []
    finally:
        _truth_cached.cache_clear()


def test_only_the_newest_maps_are_kept(store_in, monkeypatch):
    monkeypatch.setattr(seafloor_cache, "KEPT", 2)
    grid = synthesised(SPEC)
    for k in range(4):
        seafloor_cache.store(f"key {k}", grid)
    kept = {seafloor_cache.load(f"key {k}") is not None for k in range(2)}
    assert kept == {False}
    assert all(seafloor_cache.load(f"key {k}") is not None for k in (2, 3))
    assert len(list(seafloor_cache.cache_dir().glob("*.npz"))) == 2


def test_large_maps_are_not_stored(store_in, monkeypatch):
    monkeypatch.setattr(seafloor_cache, "LARGEST_BYTES", 1000)
    grid = synthesised(SPEC)
    seafloor_cache.store("big", grid)
    assert seafloor_cache.load("big") is None
    assert np.asarray(grid.z).nbytes > 1000
