"""`python -m trainer`: the same as the `trainer` command (for a shell without the project's scripts on PATH)."""

from trainer.cli import entry

entry()
