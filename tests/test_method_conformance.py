"""Every registered built-in method passes the public conformance check."""

import pytest

from tanbench.methods.registry import builtin_names
from tanbench.testing import check_method


@pytest.mark.parametrize("method", builtin_names())
def test_builtin_method_passes_check_method(method):
    report = check_method(method)
    assert len(report.checks) == 5
