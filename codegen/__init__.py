"""mems-tdc codegen: quantise a trained model and render a fixed-point C99 module."""

__version__ = "0.2.0"
