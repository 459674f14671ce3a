"""Command-line option declarations and their parsing, below the commands that use them.

The method registry, the fleet's manifests and ``codegen`` parse the same options as ``trainer``'s
sub-commands; they import them from here, so that :mod:`trainer.commands` stays on top
(``tests/project/test_layers.py``).
"""
