"""Functional core of the tracker: plain numpy/numba code, no Diagram needed."""
