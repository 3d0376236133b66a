"""The examples in ops/ docstrings run: each paper equation's public function shows its
values, and they stay true."""

from __future__ import annotations

import doctest
import importlib
import pkgutil
import re
from pathlib import Path

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


def test_the_readmes_equation_list_names_real_functions() -> None:
    """Every ``ops.…`` name in the README's "Where the equations are" table exists and is
    documented."""
    text = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    table = text.split("**Where the equations are.**", 1)[1].split("\n\n", 2)[1]
    names = re.findall(r"`(ops(?:\.\w+)+)`", table)
    assert len(names) >= 20
    for name in names:
        module, _, attr = name.rpartition(".")
        obj = getattr(importlib.import_module(module), attr)
        assert obj.__doc__, name
