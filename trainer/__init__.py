"""mems-tdc trainer: recordings, the oven-experiment simulator, compensators and their scoring."""

__version__ = "0.1.0"
