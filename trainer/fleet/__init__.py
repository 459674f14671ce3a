"""``trainer fleet``: many units through the whole pipeline on Dask, and a fleet report.

A manifest (:mod:`.manifest`, CSV or TOML) lists the units; each unit becomes a small Dask graph
(:mod:`.stages`: load and validate, diagnose, fit + evaluate + export + verify per method, assemble)
on a ``LocalCluster`` or an existing cluster (:mod:`.cluster`). Finished units are written
atomically under ``OUTDIR/units/ID/`` and keyed by a hash of their inputs and settings
(:mod:`.cache`), so a restarted run skips them. :mod:`.outliers` finds the out-of-family units and
:mod:`.report` writes ``OUTDIR/report.md`` with its figures; :mod:`.run` ties it together.
:mod:`.simulated` draws a simulated fleet for the tests, the benchmark and the cluster script.
See docs/fleet.md.
"""
