"""The examples in ops/ docstrings run: each paper equation's public function shows its
values, and they stay true."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import ops

MODULES = sorted(m.name for m in pkgutil.walk_packages(ops.__path__, "ops."))


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0


@pytest.mark.parametrize(
    "name",
    [
        "ops.checks",
        "ops.color",
        "ops.unsharp.surface",
        "ops.relief.shape",
        "ops.light_alignment.eq1",
    ],
)
def test_the_equations_have_examples(name: str) -> None:
    assert doctest.testmod(importlib.import_module(name)).attempted > 0
