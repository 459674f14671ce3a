"""Where the repository is, for tests in any folder of tests/ (one declaration)."""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
