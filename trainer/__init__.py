"""mems-tdc trainer: recordings, the oven-experiment simulator, compensators and their scoring."""

__version__ = "0.2.0"  # the one version: pyproject.toml reads it, codegen re-exports it
