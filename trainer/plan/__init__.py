"""``trainer plan``: design the chamber program that identifies the physics a compensator needs.

One job per module: ``priors`` (what to identify, with prior ranges), ``chamber`` (the chamber's
limits and the validation profile), ``programs`` (the standard profiles and the candidate
designs), ``montecarlo`` (one seeded draw: simulate, fit, score; many draws on a pool or Dask),
``summary`` (a profile's table row and the target), ``design`` (the shortest candidate that meets
the target), ``outputs`` (TOML, set-point CSV, plot, report).
"""
