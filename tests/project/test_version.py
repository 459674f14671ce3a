"""One version for the product: models (created_by), generated C and the installed package agree."""

from __future__ import annotations

import importlib.metadata

import codegen
import trainer


def test_one_version_everywhere() -> None:
    assert codegen.__version__ == trainer.__version__ == importlib.metadata.version("mems-tdc")
