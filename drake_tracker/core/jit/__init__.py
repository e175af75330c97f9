"""numba support: the on-disk kernel cache and the one place the threading layer is chosen."""
