"""The ``physics`` method: a grey-box compensator whose drift model is the catalogue's own physics.

The structure (which catalogue effects besides the bias polynomial) is chosen on the training
recording with the mismatch finder's machinery (:mod:`.structure`), fitted jointly by the finder's
model (:mod:`.fit`), and run by the simulator's formulas in batch or sample by sample exactly as
firmware runs it (:mod:`.stream`). :mod:`.compensator` is the method's class.
"""
