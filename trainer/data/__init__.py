"""Recordings: the format and its validation, CSV/NPZ I/O, foreign-logger import, smoothing."""
