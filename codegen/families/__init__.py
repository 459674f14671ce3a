"""The C families' units, one package each (parser, quantiser, golden model, template, manifest
section); :mod:`codegen.family` lists them."""
