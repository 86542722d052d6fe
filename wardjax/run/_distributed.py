"""Folders of captures on a ``dask.distributed`` cluster: one capture per task, the same files as a local batch.

:func:`wardjax.run_batch` with ``scheduler=`` hands each capture to
:func:`map_on_cluster` as a task running :func:`~wardjax.run.fit_one`, the
function the local path runs: each task writes its capture's outputs through
a staging folder of its own and commits them with ``params.json`` last, so a
worker killed mid-task leaves nothing in the capture's folder, and the task
the scheduler reruns elsewhere starts afresh. A task that finds its capture
committed by an earlier attempt of the same batch returns that result without
writing again. ``summary.csv`` and ``errors.log`` are written here, by the
client, as results arrive.

Workers run JAX in processes of their own: :class:`JaxWorker` (a dask
``WorkerPlugin``) limits XLA's and the BLAS libraries' threads to the
worker's share of its machine's cores (effective when it runs before the
worker first imports JAX, as on the clusters :func:`open_scheduler` starts,
whose workers get the same settings in their environment from the start),
turns on JAX's persistent compile cache, and counts the programs each worker
compiles (:class:`CompileCounter`).
"""

from __future__ import annotations

import collections
import contextlib
import os
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = [
    "CompileCounter",
    "JaxWorker",
    "cluster_compiles",
    "map_on_cluster",
    "open_scheduler",
    "parse_scheduler",
    "worker_env",
]

# JAX's monitoring event for one program compiled (or read from the persistent cache) for one shape.
_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
_PLUGIN = "wardjax-jax-worker"
_LOCAL = re.compile(r"local(?::(\d+))?")


def parse_scheduler(spec: str) -> tuple[str, int | str]:
    """``"local"`` / ``"local:N"`` → ``("local", N)``; an address → ``("address", spec)``.

    ``N`` defaults to the number of cores this process may use (at least 1).

    Raises
    ------
    ValueError
        One line naming ``--scheduler`` and what was expected.
    """
    spec = spec.strip()
    m = _LOCAL.fullmatch(spec)
    if m:
        n = int(m.group(1)) if m.group(1) else _cores()
        if n < 1:
            raise ValueError(f"--scheduler {spec!r}: local:N needs at least 1 worker")
        return "local", n
    if spec.startswith("local") or not spec or any(c.isspace() for c in spec):
        raise ValueError(
            f"--scheduler {spec!r}: expected local, local:N (N worker processes) or a scheduler address "
            "such as tcp://host:8786"
        )
    return "address", spec


def _cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def worker_env(threads: int) -> dict[str, str]:
    """Environment that holds a worker's JAX (XLA) and BLAS to ``threads`` threads.

    XLA's CPU backend reads ``XLA_FLAGS`` when JAX is imported: with one
    thread, Eigen's multithreading is switched off
    (``--xla_cpu_multi_thread_eigen=false``, the setting JAX's own
    documentation gives for one thread per process); otherwise the intra-op
    pool is sized (``intra_op_parallelism_threads``). NumPy's and SciPy's BLAS
    follow the ``*_NUM_THREADS`` variables.
    """
    t = str(max(1, int(threads)))
    flags = os.environ.get("XLA_FLAGS", "")
    eigen = "--xla_cpu_multi_thread_eigen=false " if threads <= 1 else ""
    flags = f"{flags} {eigen}intra_op_parallelism_threads={t}".strip()
    env = {"XLA_FLAGS": flags}
    env.update({k: t for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")})
    return env


class CompileCounter:
    """The programs JAX compiles while it is entered, by name (``jit(_solve_joint)``, …): a ``Counter``.

    Counts JAX's compile event (:mod:`jax.monitoring`), which fires once per
    program and input shape a process builds, read from the persistent cache
    or compiled afresh; a program already in the process's memory is not
    counted again.
    """

    def __init__(self) -> None:
        self.counts: collections.Counter[str] = collections.Counter()

    def _listen(self, event: str, duration_secs: float, **kwargs: str | int) -> None:
        if event == _COMPILE_EVENT:
            self.counts[str(kwargs.get("fun_name", "?"))] += 1

    def __enter__(self) -> CompileCounter:
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(self._listen)
        return self

    def __exit__(self, *exc: object) -> None:
        import jax.monitoring

        jax.monitoring.unregister_event_duration_listener(self._listen)


class JaxWorker(WorkerPlugin):
    """Settings a worker's JAX needs for fitting captures (registered as a dask ``WorkerPlugin``).

    Parameters
    ----------
    threads
        Threads per worker by worker address (its share of its machine's
        cores); a worker not listed keeps its own settings. Applied through
        :func:`worker_env` if the worker has not imported JAX yet.
    cache_dir
        JAX's persistent compile cache: a folder, ``""`` for the worker's own
        default (the user cache folder, as ``wardjax fit`` uses), ``None`` for none.
    """

    name = _PLUGIN

    def __init__(self, threads: dict[str, int] | None = None, cache_dir: str | None = "") -> None:
        self.threads = dict(threads or {})
        self.cache_dir = cache_dir
        self.counter: CompileCounter | None = None

    def setup(self, worker) -> None:
        import sys

        t = self.threads.get(worker.address)
        if t is not None and "jax" not in sys.modules:
            os.environ.update(worker_env(t))
        if self.cache_dir is not None:
            from ._cache import enable_compile_cache

            enable_compile_cache(Path(self.cache_dir) if self.cache_dir else None)
        self.counter = CompileCounter().__enter__()

    def teardown(self, worker) -> None:
        if self.counter is not None:
            self.counter.__exit__()


def _worker_compiles(dask_worker) -> dict[str, int]:
    plugin = dask_worker.plugins.get(_PLUGIN)
    return dict(plugin.counter.counts) if plugin is not None and plugin.counter is not None else {}


def cluster_compiles(client) -> dict[str, dict[str, int]]:
    """The programs each worker of ``client``'s cluster compiled since it started: ``{address: {name: count}}``."""
    return client.run(_worker_compiles)


def _has_plugin(dask_worker) -> bool:
    return _PLUGIN in dask_worker.plugins


def _cores_of(dask_worker) -> tuple[str, int]:
    return dask_worker.address, _cores()


def _register(client, cache_dir: str | None) -> None:
    """Register :class:`JaxWorker` on ``client``'s workers, each given its share of its host's cores."""
    info = client.scheduler_info()["workers"]
    per_host = collections.Counter(w["host"] for w in info.values())
    cores = client.run(_cores_of)
    threads = {a: max(1, c // per_host[info[a]["host"]]) for a, (_, c) in cores.items() if a in info}
    client.register_plugin(JaxWorker(threads, cache_dir), name=_PLUGIN)


@contextlib.contextmanager
def open_scheduler(spec: str, *, cache_dir: str | None = "") -> Iterator[Any]:
    """A ``distributed.Client`` for ``spec`` (see :func:`parse_scheduler`), closed (and its cluster) on exit.

    ``"local:N"`` starts a ``LocalCluster`` of ``N`` worker processes of one
    task each, their threads pinned to ``cores // N`` (at least one) from the
    start (:func:`worker_env`); a worker that dies is restarted by its nanny.
    An address connects to a running scheduler. Either way :class:`JaxWorker`
    is registered with ``cache_dir`` (see there).

    Raises
    ------
    ValueError
        A malformed ``spec``, or a scheduler that cannot be reached (one line).
    """
    kind, arg = parse_scheduler(spec)
    from distributed import Client, LocalCluster

    with contextlib.ExitStack() as stack:
        if kind == "local":
            n = int(arg)
            env = worker_env(max(1, _cores() // n))
            cluster = stack.enter_context(
                LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0", env=env)
            )
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(str(arg), timeout="10s"))
            except (OSError, TimeoutError) as e:
                raise ValueError(f"--scheduler {spec!r}: cannot reach the scheduler ({e})") from None
        _register(client, cache_dir)
        yield client


def _describe(client) -> str:
    n = len(client.scheduler_info()["workers"])
    return f"on {n} dask worker{'s' if n != 1 else ''}"


def map_on_cluster(
    fn: Callable,
    jobs: list[tuple],
    scheduler,
    record: Callable[[int, Any, str | None], None],
    fail: Callable[[int, str], None],
    *,
    on_start: Callable[[int, int, str], None] | None = None,
    retries: int = 2,
) -> None:
    """Run ``fn(*job)`` for every job as a task of ``scheduler``'s cluster; ``record(i, *result)`` as each ends.

    ``scheduler`` is a ``distributed.Client`` (used as it is, :class:`JaxWorker`
    registered if it is not yet) or a spec for :func:`open_scheduler`. A task
    whose worker dies is rerun on another (the scheduler's
    ``allowed-failures``); one that raises is retried ``retries`` times. A
    job the cluster still cannot finish is reported as ``fail(i, reason)``.
    Each result is released once recorded, so that a later worker loss does
    not rerun a finished task.
    """
    from distributed import as_completed

    with contextlib.ExitStack() as stack:
        if isinstance(scheduler, str):
            client = stack.enter_context(open_scheduler(scheduler))
        else:
            client = scheduler
            if not all(client.run(_has_plugin).values()):
                _register(client, "")
        if on_start:
            on_start(0, len(jobs), _describe(client))
        index = {}
        futures = []
        for i, job in enumerate(jobs):
            fut = client.submit(fn, *job, key=f"wardjax-fit-{i}-{job[1]}-{job[3]}", retries=retries, pure=False)
            index[fut.key] = i
            futures.append(fut)
        pending = as_completed(futures)
        futures.clear()
        for fut in pending:
            i = index[fut.key]
            if fut.status == "finished":
                record(i, *fut.result())
            else:
                try:
                    exc = fut.exception()
                except Exception as e:  # a cancelled future raises here
                    exc = e
                fail(i, f"the cluster could not fit this capture ({type(exc).__name__}: {exc})")
            fut.release()
