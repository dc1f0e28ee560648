"""Where batches of cases run: in this process, on local worker processes, or on Dask.

A backend maps :func:`evaluate_chunk` over chunks of cases and yields results as chunks
finish (for progress bars). Backends are chosen by name from :data:`BACKENDS`.
Every backend returns the same numbers: each case is computed by the same compiled code,
independently of the others.
"""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Iterator, Protocol, Sequence

from hexapod_control.core.closed_loop import Case, shared_reference_key

from .simulate import Outcome, evaluate_batch

Chunk = tuple[int, Sequence[Case], float]


def evaluate_chunk(chunk: Chunk) -> tuple[int, list[Outcome]]:
    """Run one chunk (start index, cases, duration) with the batched engine."""
    start, cases, duration = chunk
    return start, evaluate_batch(list(cases), duration)


class Backend(Protocol):
    """Runs chunks and yields (start index, outcomes) as they complete."""

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]: ...


class InlineBackend:
    """This process; numba's threads run the cases of a chunk in parallel."""

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        for chunk in chunks:
            yield evaluate_chunk(chunk)


def _single_threaded_worker() -> None:
    import numba

    numba.set_num_threads(1)


class ProcessBackend:
    """Local worker processes, one per core (each runs its chunk single-threaded).

    The workers start on the first :meth:`map` and serve every later one (starting a worker
    and loading the compiled engine costs seconds); :meth:`close` (or the end of a ``with``
    block, or of the interpreter) stops them.
    """

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        self._pool: ProcessPoolExecutor | None = None

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        if self._pool is None:
            ctx = multiprocessing.get_context("spawn")  # no fork of numba's thread pool
            self._pool = ProcessPoolExecutor(self.workers, mp_context=ctx,
                                             initializer=_single_threaded_worker)
        futures = [self._pool.submit(evaluate_chunk, c) for c in chunks]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()

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
    """An existing Dask cluster, given its scheduler address (tcp://host:port)."""

    def __init__(self, address: str) -> None:
        self.address = address

    def map(self, chunks: Sequence[Chunk]) -> Iterator[tuple[int, list[Outcome]]]:
        from distributed import Client, as_completed as dask_completed

        try:
            client = Client(self.address, timeout="10s")  # type: ignore[no-untyped-call]
        except OSError as err:
            raise ConnectionError(f"cannot reach the Dask scheduler at {self.address}: "
                                  f"{err}") from err
        try:
            futures = client.map(evaluate_chunk, list(chunks), pure=False)
            for fut in dask_completed(futures):  # type: ignore[no-untyped-call]
                yield fut.result()
        finally:
            client.close()  # type: ignore[no-untyped-call]


BACKENDS: dict[str, Callable[..., Backend]] = {
    "inline": InlineBackend, "processes": ProcessBackend, "dask": DaskBackend}


def make_backend(name: str = "processes", address: str | None = None) -> Backend:
    """Backend by name; 'dask' needs the scheduler ``address``."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}: one of {', '.join(BACKENDS)}")
    if name == "dask":
        if not address:
            raise ValueError("the dask backend needs a scheduler address (--dask tcp://...)")
        return DaskBackend(address)
    return BACKENDS[name]()


def run_cases(cases: Sequence[Case], duration: float, backend: Backend,
              chunk_size: int = 8,
              progress: Callable[[int], None] | None = None) -> list[Outcome]:
    """Evaluate every case on ``backend``; results in the order of ``cases``.

    Cases are grouped into chunks that share a reference trajectory (same robot, gait and
    control period). ``progress(n)`` is called with the number of cases finished in each chunk.
    """
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


__all__ = ["BACKENDS", "Backend", "DaskBackend", "InlineBackend", "ProcessBackend",
           "evaluate_chunk", "make_backend", "run_cases"]
