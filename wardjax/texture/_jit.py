"""``jit`` for the texture programs: compiled with single-threaded XLA CPU kernels, so results are bit-reproducible.

XLA's CPU backend splits FFTs and reductions over its Eigen thread pool, and
the split depends on what the pool is doing: two syntheses with the same seed
differed in most pixels (in the last bits, which the histogram matching then
amplifies into different ranks). Compiled with ``xla_cpu_multi_thread_eigen``
off, every program's arithmetic is fixed. The parallelism the texture stage
needs comes from elsewhere (channels interleaved with the host's rank threads,
several devices with :mod:`jax.sharding`). The option is per program, so the
caller's own programs and global XLA flags are untouched; other backends
ignore it.
"""

from __future__ import annotations

import functools

from .._jit import options_jit

COMPILER_OPTIONS = {"xla_cpu_multi_thread_eigen": False}


def texture_jit(fun=None, **kwargs):
    """:func:`~wardjax._jit.options_jit` with :data:`COMPILER_OPTIONS`; usable bare (``@texture_jit``) or
    with jit's keywords."""
    if fun is None:
        return functools.partial(texture_jit, **kwargs)
    return options_jit(fun, COMPILER_OPTIONS, **kwargs)
