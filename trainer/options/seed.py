"""``--seed``: one rule for every command that takes one (simulate, fit, compare, plan)."""

from __future__ import annotations

import argparse


def seed(text: str) -> int:
    """A non-negative integer (numpy's seed sequences refuse a negative one, at the first draw)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a non-negative integer")
    return value
