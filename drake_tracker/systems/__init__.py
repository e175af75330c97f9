"""Thin Drake LeafSystems around the functional core."""
