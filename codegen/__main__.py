"""`python -m codegen`: the same as the `codegen` command (for a shell without the project's scripts on PATH)."""

from codegen.cli import entry

entry()
