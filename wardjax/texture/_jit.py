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

import jax
from jax.core import Tracer

COMPILER_OPTIONS = {"xla_cpu_multi_thread_eigen": False}


def texture_jit(fun=None, **kwargs):
    """:func:`jax.jit` with :data:`COMPILER_OPTIONS`; usable bare (``@texture_jit``) or with jit's keywords.

    JAX takes compiler options only for a top-level program: called on
    tracers (inside another program, which has the options itself), the
    function is traced as a plain ``jax.jit``.
    """
    if fun is None:
        return functools.partial(texture_jit, **kwargs)
    top = jax.jit(fun, compiler_options=COMPILER_OPTIONS, **kwargs)
    nested = jax.jit(fun, **kwargs)

    @functools.wraps(fun)
    def call(*args, **kw):
        traced = any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves((args, kw)))
        return (nested if traced else top)(*args, **kw)

    return call
