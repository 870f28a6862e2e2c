"""vehid: vehicle and suspension parameter identification."""

import os as _os

# Our matrices are tiny (14 x 14) and campaigns parallelise over processes: BLAS worker threads only
# contend for the cores (measured: a 2-process campaign ran 5x slower with OpenBLAS's default threads).
# Set before NumPy loads; a user's explicit setting wins. Workers also enforce it with threadpoolctl.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

# Every evaluation allocates arrays of a few MB: glibc would mmap each afresh and fault its pages in again on every
# call (4x the exact sensitivities' cost). Keep freed blocks below 32 MB for reuse (core/allocator.py).
from .core.allocator import keep_freed_memory as _keep_freed_memory  # noqa: E402

_keep_freed_memory()

__version__ = "0.1.0"
