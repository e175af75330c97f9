"""The one place where drake_tracker chooses numba's threading layer.

Every module of the package that defines ``parallel=True`` kernels imports this module
first, so the choice is made before any parallel kernel runs (numba fixes its threading
layer at the first parallel launch).

Why: one image update makes about 60 small parallel calls (one per CPF block and
annealing layer, ~35 particles each). Numba's default layer on Linux is OpenMP, whose
worker threads spin-wait at every barrier; on a machine where the cores are shared, two
threads made an image update 3-5x *slower* than one. The ``workqueue`` layer ships with
numba (no extra dependency) and its workers sleep instead of spinning, so a second thread
never costs more than it brings (measured by ``drake-tracker bench``, 1 vs 2 threads).

Its limit: workqueue must not be entered from two Python threads at once. The tracker
runs its kernels from one thread (the Drake Simulator's, or the offline loop's); parallel
evaluations use processes. A user who needs thread-safe concurrent calls can choose
another layer with the environment variable ``NUMBA_THREADING_LAYER`` (e.g. ``tbb`` after
``pip install tbb``, or ``omp`` with ``OMP_WAIT_POLICY=PASSIVE``), which always wins over
this default.
"""

from __future__ import annotations

import os

import numba

#: The layer chosen when the user has not set ``NUMBA_THREADING_LAYER``.
DEFAULT_THREADING_LAYER = "workqueue"


def configure_threading_layer() -> str:
    """Selects :data:`DEFAULT_THREADING_LAYER` unless the user's environment names a layer.

    Returns the configured layer name (what numba will load at its first parallel
    launch). Harmless once a layer is loaded: numba then keeps the one it has.
    """
    requested = os.environ.get("NUMBA_THREADING_LAYER", "").strip()
    if requested:
        return requested
    if numba.config.THREADING_LAYER == "default":
        numba.config.THREADING_LAYER = DEFAULT_THREADING_LAYER
    return str(numba.config.THREADING_LAYER)


configure_threading_layer()
