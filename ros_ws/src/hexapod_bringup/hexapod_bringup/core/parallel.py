"""Where batches of cases run: in this process, on local worker processes, or on Dask.

A backend maps :func:`evaluate_chunk` over chunks of cases (:meth:`Backend.map`), or any
picklable function over items (:meth:`Backend.calls`: the single runs whose whole time
series a report needs), and yields results as they finish (for progress bars). Backends are
chosen by name from :data:`BACKENDS`. Every backend returns the same numbers: each case is
computed by the same compiled code, independently of the others.

Dask: ``--dask tcp://host:port`` joins an existing cluster; ``--dask local:N`` starts a
cluster of N single-threaded worker processes on this machine (scheduler on 127.0.0.1, no
dashboard) for the length of the command (:class:`DaskBackend`).
"""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterator, Protocol, Sequence, TypeVar

from hexapod_control.core.closed_loop import Case, shared_reference_key

from .simulate import Outcome, evaluate_batch

Chunk = tuple[int, Sequence[Case], float]
T = TypeVar("T")
R = TypeVar("R")
#: ``--dask local:N``: a local cluster of N workers instead of a scheduler address.
LOCAL_PREFIX = "local:"


def evaluate_chunk(chunk: Chunk) -> tuple[int, list[Outcome]]:
    """Run one chunk (start index, cases, duration) with the batched engine."""
    start, cases, duration = chunk
    return start, evaluate_batch(list(cases), duration)


class Backend(Protocol):
    """Runs chunks (or calls) and yields their results as they complete."""

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]: ...

    def calls(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R]]: ...


class _Indexed:
    """``fn`` applied to (index, item) -> (index, fn(item)); picklable if ``fn`` is."""

    def __init__(self, fn: Callable[[Any], Any]) -> None:
        self.fn = fn

    def __call__(self, job: tuple[int, Any]) -> tuple[int, Any]:
        return job[0], self.fn(job[1])


def _single_threaded(job: tuple[Callable[[Any], Any], Any]) -> Any:
    """Run ``fn(item)`` with numba on one thread (a Dask worker thread runs one task)."""
    import numba

    numba.set_num_threads(1)
    fn, item = job
    return fn(item)


#: Fewest cases per chunk sent to a worker (one compiled block on its one thread).
CHUNK_CASES = 8
#: Most cases per chunk sent to a worker: a block of 32 cases runs ~10 % faster a case than
#: blocks of 8 now that a sweep scores its cases instead of recording them (the 128-point
#: sweep's runs: 3.0 s against 3.3-3.4 s; 64 measured no faster than 32).
MAX_CHUNK_CASES = 32


class InlineBackend:
    """This process; numba's threads run the cases of a chunk in parallel."""

    @property
    def chunk_size(self) -> int:
        """Cases per chunk: two blocks of :data:`CHUNK_CASES` for each of numba's threads
        (with chunks of 8, a chunk was one block and ran on one thread)."""
        import numba

        return 2 * CHUNK_CASES * numba.get_num_threads()

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        for chunk in chunks:
            yield evaluate_chunk(chunk)

    def calls(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R]]:
        """(index, fn(item)) for each item, in order."""
        for k, item in enumerate(items):
            yield k, fn(item)


def _single_threaded_worker() -> None:
    import numba

    numba.set_num_threads(1)


def _threads_running() -> bool:
    """Whether this process runs another Python thread or has started numba's thread pool
    (then a forked child would inherit locks and a pool without their threads)."""
    import threading

    import numba

    if threading.active_count() > 1:
        return True
    try:
        numba.threading_layer()  # type: ignore[attr-defined]  # ValueError until started
    except ValueError:
        return False
    return True


def pool_start_method() -> str:
    """``fork`` while this process runs no other thread (the workers then start in
    milliseconds with the engine already imported), else ``spawn`` (each worker a new
    interpreter that imports the engine: ~0.7 s)."""
    return "spawn" if _threads_running() else "fork"


class ProcessBackend:
    """Local worker processes, one per core (each runs its chunk single-threaded).

    The workers start on :meth:`start` (or the first :meth:`map`) and serve every later one;
    :meth:`close` (or the end of a ``with`` block, or of the interpreter) stops them. They
    are forked from this process when it runs no other thread yet (:func:`pool_start_method`;
    a command starts them before its progress bars), else spawned.
    """

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        self._pool: ProcessPoolExecutor | None = None
        self.start_method: str | None = None

    def start(self) -> "ProcessBackend":
        """Start the workers now (idempotent)."""
        if self._pool is None:
            self.start_method = pool_start_method()
            ctx = multiprocessing.get_context(self.start_method)
            self._pool = ProcessPoolExecutor(self.workers, mp_context=ctx,
                                             initializer=_single_threaded_worker)
            # a forking pool starts all its workers at the first submit
            self._pool.submit(int).result()
        return self

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        for _, result in self.calls(evaluate_chunk, chunks):
            yield result

    def calls(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R]]:
        """(index, fn(item)) as the workers finish them."""
        pool = self.start()._pool
        assert pool is not None
        futures = [pool.submit(_Indexed(fn), (k, x)) for k, x in enumerate(items)]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()

    def submit(self, fn: Callable[[T], R], item: T) -> "Future[R]":
        """``fn(item)`` on a worker, queued behind what was submitted before; its future."""
        pool = self.start()._pool
        assert pool is not None
        return pool.submit(fn, item)

    def close(self) -> None:
        """Stop the worker processes (idempotent)."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def __enter__(self) -> "ProcessBackend":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class DaskBackend:
    """A Dask cluster: an existing one by scheduler address (``tcp://host:port``), or
    ``local:N``, a cluster of N single-threaded worker processes started on this machine
    (scheduler on 127.0.0.1, no dashboard) and stopped by :meth:`close`.

    One client serves every :meth:`map` of the command (connecting costs a round trip to
    the scheduler). Each task runs numba on one thread: a worker runs as many tasks at once
    as it has threads.
    """

    def __init__(self, address: str) -> None:
        self.address = address
        self._client: Any = None
        self._cluster: Any = None

    def _connect(self) -> Any:
        if self._client is not None:
            return self._client
        from distributed import Client, LocalCluster

        if self.address.startswith(LOCAL_PREFIX):
            import dask

            n = local_workers(self.address)
            # Without the workers' sampling profiler (a stack walk every 10 ms in each
            # worker, for a dashboard this cluster does not have).
            with dask.config.set({"distributed.worker.profile.enabled": False}):
                self._cluster = LocalCluster(  # type: ignore[no-untyped-call]
                    n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                    dashboard_address=None)
            self._client = Client(self._cluster)  # type: ignore[no-untyped-call]
            return self._client
        try:
            self._client = Client(self.address, timeout="10s")  # type: ignore[no-untyped-call]
        except OSError as err:
            raise ConnectionError(f"cannot reach the Dask scheduler at {self.address}: "
                                  f"{err}") from err
        return self._client

    @property
    def workers(self) -> int:
        """Worker processes of the cluster (connects if needed)."""
        return len(self._connect().scheduler_info()["workers"])

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        for _, result in self.calls(evaluate_chunk, chunks):
            yield result

    def calls(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R]]:
        """(index, fn(item)) as the cluster finishes them."""
        from distributed import as_completed as dask_completed

        client = self._connect()
        futures = client.map(_single_threaded, [(_Indexed(fn), (k, x))
                                                for k, x in enumerate(items)], pure=False)
        try:
            for fut in dask_completed(futures):  # type: ignore[no-untyped-call]
                yield fut.result()
        finally:
            client.cancel(futures)

    def close(self) -> None:
        """Close the client, and stop the local cluster if this backend started it."""
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self) -> "DaskBackend":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def local_workers(address: str) -> int:
    """N of a ``local:N`` address; ValueError unless N is a whole number >= 1."""
    text = address[len(LOCAL_PREFIX):]
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"--dask {address}: expected local:N with N >= 1 workers, "
                         f"e.g. local:2")
    return int(text)


BACKENDS: dict[str, Callable[..., Backend]] = {
    "inline": InlineBackend, "processes": ProcessBackend, "dask": DaskBackend}


def make_backend(name: str = "processes", address: str | None = None) -> Backend:
    """Backend by name; 'dask' needs the scheduler ``address``."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}: one of {', '.join(BACKENDS)}")
    if name == "dask":
        if not address:
            raise ValueError("the dask backend needs a scheduler address (--dask tcp://...) "
                             "or a local cluster (--dask local:N)")
        if address.startswith(LOCAL_PREFIX):
            local_workers(address)  # checked before anything starts
        return DaskBackend(address)
    return BACKENDS[name]()


class MemoBackend:
    """Another backend that runs each (case, duration) once: a chunk's cases seen before
    are taken from memory, the rest run on ``inner`` (the report's experiments share many
    points: the base case, the ground sweeps at 400 N m, PD^alpha at its own alpha; a
    quarter of ``reproduce --quick``'s runs). A case's outcome does not depend on the
    cases batched with it (tests/test_engine.py), so the numbers are those of a rerun."""

    def __init__(self, inner: Backend) -> None:
        self.inner = inner
        self.known: dict[tuple[Case, float], Outcome] = {}
        #: runs taken from memory instead of being run again
        self.reused = 0

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        known = self.known
        todo: list[Chunk] = []
        scheduled: set[tuple[Case, float]] = set()
        waiting: list[Chunk] = []
        for chunk in chunks:
            _, cases, duration = chunk
            missing = [c for c in cases
                       if (c, duration) not in known and (c, duration) not in scheduled]
            scheduled.update((c, duration) for c in missing)
            if missing:
                todo.append((len(todo), missing, duration))
            waiting.append(chunk)
        self.reused += sum(len(c[1]) for c in chunks) - len(scheduled)

        def ready() -> Iterator[tuple[int, list[Outcome]]]:
            for chunk in list(waiting):
                start, cases, duration = chunk
                if all((c, duration) in known for c in cases):
                    waiting.remove(chunk)
                    yield start, [known[(c, duration)] for c in cases]

        yield from ready()
        for start, outcomes in self.inner.map(todo):
            _, cases, duration = todo[start]
            for c, o in zip(cases, outcomes):
                known[(c, duration)] = o
            yield from ready()

    def calls(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R]]:
        """The inner backend's (single runs are not kept)."""
        return self.inner.calls(fn, items)

    def chunk_size_for(self, cases: int) -> int:
        """The inner backend's chunk size."""
        return chunk_size_of(self.inner, cases)


def local_submit(backend: object) -> Callable[[Callable[[Any], Any], Any], "Future[Any]"] | None:
    """``submit(fn, item)`` of ``backend``'s local worker processes (through wrappers that
    keep theirs as ``inner``, as :class:`MemoBackend` does), or None if it has none (inline,
    Dask)."""
    while hasattr(backend, "inner"):
        backend = backend.inner
    return backend.submit if isinstance(backend, ProcessBackend) else None


def chunk_size_of(backend: object, cases: int = 0) -> int:
    """Cases per chunk when ``cases`` cases run on ``backend``: its own ``chunk_size`` (or
    ``chunk_size_for(cases)``) if it has one; else, for single-threaded workers, the same
    number of chunks for every worker (one or two each, more where a chunk would exceed
    :data:`MAX_CHUNK_CASES`), two only where each keeps :data:`CHUNK_CASES` cases: chunks of
    8, 8 and 1 left a worker idle while the other ran 8 (``reproduce``'s 9 PD^alpha runs,
    plain Python one by one: 5 and 4 now)."""
    own = getattr(backend, "chunk_size_for", None)
    if own is not None:
        return int(own(cases))
    fixed = getattr(backend, "chunk_size", None)
    if fixed is not None:
        return int(fixed)
    if cases <= 0:
        return CHUNK_CASES
    workers = max(1, int(getattr(backend, "workers", 1)))
    each = max(1, min(2, cases // (workers * CHUNK_CASES)),
               -(-cases // (workers * MAX_CHUNK_CASES)))
    return -(-cases // (workers * each))


def run_cases(cases: Sequence[Case], duration: float, backend: Backend,
              chunk_size: int | None = None,
              progress: Callable[[int], None] | None = None) -> list[Outcome]:
    """Evaluate every case on ``backend``; results in the order of ``cases``.

    Cases are grouped into chunks (of ``chunk_size``, default :func:`chunk_size_of` the
    backend) that share a reference trajectory (same robot, gait and control period).
    ``progress(n)`` is called with the number of cases finished in each chunk.
    """
    if chunk_size is None:
        chunk_size = chunk_size_of(backend, len(cases))
    groups: dict[tuple[object, ...], list[int]] = {}
    for k, c in enumerate(cases):
        groups.setdefault(shared_reference_key(c.params), []).append(k)
    chunks: list[Chunk] = []
    order: list[list[int]] = []
    for members in groups.values():
        for i in range(0, len(members), chunk_size):
            ids = members[i:i + chunk_size]
            chunks.append((len(order), [cases[k] for k in ids], duration))
            order.append(ids)
    results: list[Outcome | None] = [None] * len(cases)
    for start, outcomes in backend.map(chunks):
        for k, o in zip(order[start], outcomes):
            results[k] = o
        if progress is not None:
            progress(len(outcomes))
    return [r for r in results if r is not None]


__all__ = ["BACKENDS", "Backend", "CHUNK_CASES", "DaskBackend", "InlineBackend",
           "LOCAL_PREFIX", "MAX_CHUNK_CASES", "MemoBackend", "ProcessBackend", "chunk_size_of",
           "evaluate_chunk", "local_submit", "local_workers", "make_backend",
           "pool_start_method", "run_cases"]
