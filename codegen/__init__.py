"""mems-tdc codegen: quantise a trained model and render a fixed-point C99 module."""

from trainer import __version__  # one version for the product (generated files and models agree)

__all__ = ["__version__"]
