"""BLAS threads: one, for tdmon's small matrices.

tdmon's linear algebra is small matrices (Kalman updates of a few hundred friction bins), where
BLAS threads only contend for the cores: measured 34 ms against 0.6 ms per friction-profile
update on 2 busy cores. threadpoolctl sets the limit on the BLAS libraries already loaded, so it
works after numpy is imported (an environment variable is read only when the library loads),
also when tdmon is used as a library.
"""

from __future__ import annotations

import os

#: Variables by which a user chooses the thread count; any of them set wins over tdmon's limit.
USER_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_blas_threads(threads: int = 1) -> bool:
    """Limit numpy's BLAS to ``threads`` threads, unless the user chose a count.

    Imports numpy (its BLAS must be loaded for threadpoolctl to see it). Returns whether the
    limit was applied (False when one of `USER_VARIABLES` is set).
    """
    if any(os.environ.get(name) for name in USER_VARIABLES):
        return False
    import numpy  # noqa: F401  (loads the BLAS the limit applies to)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=threads, user_api="blas")
    return True
