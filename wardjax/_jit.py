"""``jax.jit`` with XLA compiler options, usable at the top level and inside another program."""

from __future__ import annotations

import functools

import jax
from jax.core import Tracer


def options_jit(fun, compiler_options: dict, **kwargs):
    """:func:`jax.jit` of ``fun`` compiled with ``compiler_options`` (``jit``'s other keywords as given).

    JAX takes compiler options only for a top-level program: called on tracers (inside another
    program, which has its own options), the function is traced as a plain ``jax.jit``.
    """
    top = jax.jit(fun, compiler_options=compiler_options, **kwargs)
    nested = jax.jit(fun, **kwargs)

    @functools.wraps(fun)
    def call(*args, **kw):
        traced = any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves((args, kw)))
        return (nested if traced else top)(*args, **kw)

    return call


__all__ = ["options_jit"]
