"""SIMD across particles: numba intrinsics that work on 8 particles (lanes) at once."""
