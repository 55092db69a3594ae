"""The examples in the docstrings run and print what they claim."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import vtkraycast

MODULES = sorted(
    name
    for _, name, _ in pkgutil.walk_packages(vtkraycast.__path__, "vtkraycast.")
    if not name.endswith(("__main__", "_core"))
)


@pytest.mark.parametrize("name", ["vtkraycast", *MODULES])
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
