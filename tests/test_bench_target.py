"""`make bench` says what the kernels were compiled for (their figures depend on it)."""

from __future__ import annotations

import llvmlite.binding as llvm
from numba.core import config

from tanbench.bench import compile_target


def test_the_host_and_its_widest_vectors(monkeypatch):
    monkeypatch.setattr(config, "CPU_NAME", None)
    monkeypatch.setattr(config, "CPU_FEATURES", None)
    text = compile_target()
    assert text.startswith(f"{llvm.get_host_cpu_name()} (this host), ")
    features = llvm.get_host_cpu_features()
    assert text.endswith("AVX-512" if features.get("avx512f") else "AVX2" if features.get("avx2") else "AVX-512")


def test_the_environment_overrides_are_named(monkeypatch):
    monkeypatch.setattr(config, "CPU_NAME", "haswell")
    monkeypatch.setattr(config, "CPU_FEATURES", "-avx512f")
    assert compile_target() == "haswell, features '-avx512f' (NUMBA_CPU_FEATURES)"
    monkeypatch.setattr(config, "CPU_FEATURES", None)
    assert compile_target() == "haswell (NUMBA_CPU_NAME) with its own default features"


def test_the_bench_runs_the_measured_options():
    """make bench times tight-dvl with progressive correction and with the adaptive count beside its defaults."""
    from tanbench.bench import OPTION_RUNS, run_figures

    assert {k for o in OPTION_RUNS for k in o} == {"tempering_ess", "kld_epsilon"}
    plain = run_figures("tight-dvl", 200, 1)
    tempered = run_figures("tight-dvl", 200, 1, options={"tempering_ess": 0.5})
    assert plain["options"] == "" and tempered["options"] == "tempering_ess=0.5"
    assert tempered["cost_units"] == 1.6 * plain["cost_units"] and tempered["ns_per_unit_cpu"] > 0
