"""Scoring: Allan analysis, drift left and input kept, the comparison, figures and the report."""
