"""Independent runs on forked worker processes, the same result with any number of them."""
from __future__ import annotations

__all__ = ["Workers"]


class Workers:
    """Up to ``jobs`` worker processes for independent runs (a fit's folds and Kalman runs, the peers of
    ``validate --data``), started at the first :meth:`map` and kept until the block ends: forked, they start
    with this process's modules and compiled expressions, and keep what they compile (a model's printed
    expressions, a Kalman model's graph) from one map to the next. One job, or a platform without fork:
    everything in this process."""

    def __init__(self, jobs: int):
        import multiprocessing
        self.jobs = jobs if "fork" in multiprocessing.get_all_start_methods() else 1
        self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.shutdown()
        return False

    def map(self, calls) -> list:
        """``[fn(*args) for fn, args in calls]``, in order. Each call is deterministic and independent of the
        others, so the result is the same with any ``jobs``; a call's error is raised here as it was raised
        there. ``calls`` may be a generator: each call is handed to the workers as soon as it is made, so
        what this process does to make the next (a fold's tyre fit) overlaps the workers' runs."""
        if self.jobs <= 1:
            return [fn(*args) for fn, args in calls]
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor
            self._pool = ProcessPoolExecutor(max_workers=self.jobs, mp_context=multiprocessing.get_context("fork"))
        futures = [self._pool.submit(fn, *args) for fn, args in calls]
        return [f.result() for f in futures]
