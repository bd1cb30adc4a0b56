"""Emission of generated packages: :mod:`.package` writes ``generated/<robot>/`` from the optimised
(:mod:`.optimize`) expression graph through the :mod:`.backends` (NumPy, C, CasADi); :mod:`.check`
compares a committed ``generated/`` with a fresh generation (``make check-generated``)."""
