"""Chunks of a batch on their way to the devices: host-to-device copies overlapped with compute.

A fit in chunks reads each chunk's rows once. On a CPU the compiled call takes NumPy arrays as
they are. On an accelerator, rows held in (pageable) host memory must cross to the device first,
and one ``device_put`` of a large array copies at a few GB/s on one host thread, slower than the
fit itself: there the copies of the next chunks run in worker threads, one per array, while
the current chunk computes. Arrays already on a device (:class:`jax.Array`) are not copied.

On a CPU the chunks' programs run on all cores at once (:func:`stream`): XLA's CPU client runs
the calls of one execution stream one after another, each after the last one enqueued, so chunks
dispatched on one stream use one core at a time whatever their number.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import os
from collections.abc import Callable, Iterator, Sequence

import jax
from jaxlib import xla_client

from ._data import pad_rows

AHEAD = 2  # chunks copied ahead of the one computing
WORKERS = 8  # host threads making the copies (each holds one array of one chunk)


# The current thread's execution stream, as a context manager (None in a jaxlib without it: one stream).
_STREAM_ID = getattr(xla_client, "execution_stream_id", None)


def streams(devices: Sequence) -> int:
    """Execution streams a fit's chunks take turns on: one per core this process may run on, on a CPU
    (the client's pool of threads that run calls has one per core); one elsewhere (an accelerator
    runs its calls in order anyway)."""
    if devices[0].platform != "cpu" or _STREAM_ID is None:
        return 1
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else range(os.cpu_count() or 1)
    return max(len(cores), 1)


def stream(i: int, n: int) -> contextlib.AbstractContextManager:
    """Context in which compiled calls run on execution stream ``i mod n`` (the default stream for
    ``n = 1``): calls on different streams wait only for their inputs, so chunks ``i`` taking turns
    over ``n`` streams run on up to ``n`` cores at once. Each call is the same program on the same
    rows as on one stream: the results are the same to the bit."""
    if n <= 1 or _STREAM_ID is None:
        return contextlib.nullcontext()
    return _STREAM_ID(1 + i % n)


def host_fed(data: Sequence, devices: Sequence) -> bool:
    """True when some array of ``data`` is in host memory and the devices are accelerators."""
    on_host = any(a is not None and not isinstance(a, jax.Array) for a in data)
    return on_host and devices[0].platform != "cpu"


def chunks(data: Sequence, spans: Sequence[tuple[int, int, int]], put: Callable, *, threaded: bool) -> Iterator[list]:
    """Each span ``(start, stop, rows)``'s rows of every array of ``data``, padded to ``rows`` and placed.

    ``put`` places one array (see :func:`wardjax.fit._scanline._placement`). ``threaded``: the
    copies run in :data:`WORKERS` threads, :data:`AHEAD` chunks ahead of the consumer, so an
    accelerator computes one chunk while the next ones cross from host memory. The results are
    the same arrays either way.
    """

    def place(a, start, stop, rows):
        if a is None:
            return None
        with jax.enable_x64(True):  # a worker thread does not inherit the caller's float64 context
            return put(pad_rows(a[start:stop], rows))

    if not threaded:
        for start, stop, rows in spans:
            yield [place(a, start, stop, rows) for a in data]
        return
    with concurrent.futures.ThreadPoolExecutor(WORKERS, thread_name_prefix="wardjax-feed") as pool:
        pending: collections.deque = collections.deque()
        for start, stop, rows in spans:
            pending.append([pool.submit(place, a, start, stop, rows) for a in data])
            if len(pending) > AHEAD:
                yield [f.result() for f in pending.popleft()]
        while pending:
            yield [f.result() for f in pending.popleft()]
