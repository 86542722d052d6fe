"""Scanline data at the boundary: validation, cleaning, and padding to shared shapes.

Every fit entry point (:func:`~wardjax.fit_scanlines`, the joint refit)
validates its arrays here, turns masked or unusable samples into zero weight,
and pads the batch and sample axes to :func:`wardjax._shapes.bucket` sizes
so that batches of slightly different shapes share compiled programs.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .. import _shapes
from .._jit import options_jit
from . import _varpro

__all__ = [
    "SAMPLE_FILL",
    "SMALL_SAMPLES",
    "Kernel",
    "bucket_rows",
    "buckets",
    "check_choice",
    "clean",
    "clean_jit",
    "moments_chunk",
    "pad_rows",
    "pad_samples",
    "validate",
]


def check_choice(name, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name}={value!r} is not one of {', '.join(map(repr, allowed))}")


def _on_device(a) -> bool:
    """True for a :class:`jax.Array`: kept where it is (no copy to the host and back)."""
    return isinstance(a, jax.Array)


def _as_batch(name: str, x, shape: tuple[int, ...] | None = None):
    arr = x if _on_device(x) else np.asarray(x)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}, expected {shape}")
    return arr


@jax.jit
def _any_negative_jit(a):
    return jnp.any(a < 0)


NEGATIVE_WEIGHTS = "weights must be non-negative (they are 1/σ² per sample)"


def negative_flag(a):
    """``any(a < 0)`` of an array placed on its device, left there (a flag for :func:`check_sign`)."""
    return _any_negative_jit(a)


def check_sign(flags) -> None:
    """Raise the negative-weights error if any chunk's flag (:func:`negative_flag`, read from its device) is set."""
    if any(bool(f) for f in flags):
        raise ValueError(NEGATIVE_WEIGHTS)


def _any_negative(a) -> bool:
    """``any(a < 0)`` where ``a`` is, on the host or on its device (float64 kept)."""
    if not _on_device(a):
        return bool(np.any(a < 0))
    with jax.enable_x64(True):
        return bool(_any_negative_jit(a))


def validate(f_r, wi, wo, mask, weights, *, sign_later: bool = False):
    """Check shapes and types at the boundary (cheap); cleaning happens inside the kernel.

    NumPy inputs stay NumPy; :class:`jax.Array` inputs stay on their device (a
    pipeline that keeps its data on a GPU pays no host round trip). ``sign_later``: NumPy
    weights are not scanned here for negative values; the caller checks each chunk on its
    device (:func:`check_sign`) and raises the same error before returning.
    """
    f = f_r if _on_device(f_r) else np.asarray(f_r)
    if f.ndim != 3 or f.shape[-1] != 3:
        raise ValueError(f"f_r must have shape (S, N, 3) (scanlines, samples, RGB), got {f.shape}")
    shape = f.shape
    f = _as_batch("f_r", f)
    wi = _as_batch("wi", wi, shape)
    wo = _as_batch("wo", wo, shape)
    s, n, _ = shape
    if weights is not None:
        wt = _as_batch("weights", weights)
        if wt.shape == (s, n):
            wt = wt[..., None]
        if wt.shape not in ((s, n, 1), (s, n, 3)):
            raise ValueError(
                f"weights must have shape (S, N) or (S, N, 3) = {(s, n)} or {shape}, got {np.shape(weights)}"
            )
        if not (sign_later and not _on_device(wt)) and _any_negative(wt):
            raise ValueError(NEGATIVE_WEIGHTS)
        weights = wt
    if mask is not None:
        m = mask if _on_device(mask) else np.asarray(mask)
        if m.shape == (s, n):
            m = m[..., None]
        if m.shape not in ((s, n, 1), (s, n, 3)):
            raise ValueError(f"mask must have shape (S, N) or (S, N, 3), got {np.shape(mask)}")
        mask = m if m.dtype == bool else m.astype(bool)
    return f, wi, wo, mask, weights


def clean(f, wi, wo, mask, weights, dtype):
    """Inside the jit: cast, zero the weight of unusable samples, make their values finite.

    A sample (or, with per-channel weights or mask, a value) is unusable when
    it is masked, non-finite, or has a non-finite direction. Returns
    ``(f, wi, wo, w)`` with ``w`` of shape ``(S, N, C)``.
    """
    f, wi, wo = (jnp.asarray(a, dtype) for a in (f, wi, wo))
    c = max(1 if weights is None else weights.shape[-1], 1 if mask is None else mask.shape[-1])
    w = jnp.ones(f.shape[:2] + (c,), dtype)
    if weights is not None:
        w = w * jnp.asarray(weights, dtype)
    if mask is not None:
        w = jnp.where(mask, w, 0.0)
    finite = jnp.isfinite(f)
    fin = jnp.all(finite, axis=-1, keepdims=True) if c == 1 else finite
    dirs_ok = jnp.all(jnp.isfinite(wi) & jnp.isfinite(wo), axis=-1, keepdims=True)
    w = jnp.where(fin & dirs_ok & jnp.isfinite(w), w, 0.0)
    up = jnp.asarray([0.0, 0.0, 1.0], dtype)[None, None, :]
    return jnp.where(finite, f, 0.0), jnp.where(dirs_ok, wi, up), jnp.where(dirs_ok, wo, up), w


# XLA:CPU hands sums over an axis (dot products, reductions) to YNNPACK. Over a sample axis of a few
# values its per-call cost exceeds the sums themselves: the kernels for small problems (at most
# SMALL_SAMPLES samples, on a CPU) are compiled without those fusions. Per fit, 1,024 problems of 9
# samples (CPU time, best of 40): moments 0.7–0.9 → 0.3–0.4 µs, the search 2.4–2.9 → 1.8 µs
# (Gauss–Newton) and 6.0 → 3.6–4.0 µs (check, sandwich and profiles); 16 and 32 samples gain less,
# and from 64 samples on YNNPACK is the faster.
SMALL_SAMPLES = 32
_SMALL_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}

# The kernels' sums over the samples are variadic reductions XLA:CPU forms itself (the search's, the
# curvature check's, the sandwich's): in IEEE order each is one serial chain of adds, one value at a time.
# Allowed to reassociate them (LLVM's fast-math flags with NaNs, infinities, division and library
# functions still exact), it vectorises them: sums that differ in the last bits, and per 1,024 scanlines
# of 256 samples (one core) the sandwich's reduction 1.6 → 1.1 ms, the check's 0.38 → 0.25 ms; the
# search's sums, which were dot products, cost more than so (see ``_varpro.stats``). Other backends
# ignore the options.
_REASSOCIATE_OPTIONS = {
    "xla_cpu_enable_fast_math": True,
    "xla_cpu_fast_math_honor_nans": True,
    "xla_cpu_fast_math_honor_infs": True,
    "xla_cpu_fast_math_honor_division": True,
    "xla_cpu_fast_math_honor_functions": True,
}


@functools.cache
def _known(options: tuple) -> dict:
    """``dict(options)`` where this XLA knows them all (one trivial compile to ask), else none."""
    try:
        jax.jit(lambda x: x + 1, compiler_options=dict(options)).lower(np.float32(0)).compile()
    except Exception:  # an XLA without an option (older, or renamed): the default programs serve
        return {}
    return dict(options)


def _small_options() -> dict:
    """:data:`_SMALL_OPTIONS` where this XLA knows them, else none."""
    return _known(tuple(_SMALL_OPTIONS.items()))


def _reassociate_options() -> dict:
    """:data:`_REASSOCIATE_OPTIONS` where this XLA knows them, else none."""
    return _known(tuple(_REASSOCIATE_OPTIONS.items()))


class Kernel:
    """A function jitted twice: the general program, and one for small problems on a CPU.

    Called directly it is the general program; :meth:`pick` returns the program compiled without
    YNNPACK fusions (see :data:`SMALL_SAMPLES`) when ``small`` is true. Both are compiled with
    :data:`_REASSOCIATE_OPTIONS` and compute the same sums, in a different order (results equal to
    rounding).
    """

    def __init__(self, fn, **jit_kw):
        self._fn, self._kw = fn, jit_kw
        functools.update_wrapper(self, fn)

    @functools.cached_property
    def general(self):
        return options_jit(self._fn, _reassociate_options(), **self._kw)

    @functools.cached_property
    def small(self):
        return options_jit(self._fn, {**_reassociate_options(), **_small_options()}, **self._kw)

    def pick(self, small: bool):
        """The program for a problem of few samples on a CPU (``small``), or the general one."""
        return self.small if small else self.general

    def __call__(self, *args, **kwargs):
        return self.general(*args, **kwargs)


def kernel(**jit_kw):
    """Decorator: :class:`Kernel` of the function, ``jit_kw`` as for :func:`jax.jit`."""
    return lambda fn: Kernel(fn, **jit_kw)


# The fast path is compiled as separate stages. Stage A cleans the inputs and
# builds each scanline's geometry, then its moment matrices; stage B runs the
# search on them. Compiled as one program, XLA:CPU lays out and fuses the moments so
# that every evaluation of the search costs ~5× more (measured: 1.5 vs 6–10 ms
# CPU per evaluation of 1,024 scanlines); materialising them between two
# programs keeps each evaluation a plain exp plus two small mat-vecs.


@functools.partial(jax.jit, static_argnames=("dtype",))
def clean_jit(f, wi, wo, mask, weights, *, dtype):
    return clean(f, wi, wo, mask, weights, dtype)


def bucket_rows(s: int, chunk: int) -> int:
    """Rows a batch of ``s`` is padded to: 64, 256, 1024, … (×4), at most ``chunk``.

    Coarse buckets keep the number of compiled shapes small (each costs
    seconds); the padded rows have zero weight and cost little.
    """
    rows = 64
    while rows < s and rows < chunk:
        rows *= 4
    return min(rows, chunk)


def buckets(s: int, chunk: int) -> list[tuple[int, int, int]]:
    """Split ``s`` rows into chunks of ``chunk`` rows; a short batch is padded to a bucket size."""
    if s >= chunk:
        return [(i, min(i + chunk, s), chunk) for i in range(0, s, chunk)]
    return [(0, s, bucket_rows(s, chunk))]


SAMPLE_FILL = (np.nan, np.nan, np.nan, False, 0.0)


def pad_samples(data, n: int):
    """``data`` with the sample axis padded to ``n`` by unusable samples (zero weight after :func:`clean`)."""
    return tuple(
        None if a is None else _shapes.pad_to_shape(a, a.shape[:1] + (n,), fill) for a, fill in zip(data, SAMPLE_FILL)
    )


@kernel(static_argnames=("iso",))
def moments_chunk(f, u, v, g, w, n, *, iso):
    """:func:`~wardjax.fit._varpro.prepare` of each scanline; ``n`` (traced) samples are data, the rest padding."""
    return jax.vmap(lambda *a: _varpro.prepare(*a, iso=iso, n=n))(f, u, v, g, w)


def pad_rows(a, rows: int):
    """``a`` with zero rows appended to ``rows`` (NumPy, or a :class:`jax.Array` on its device)."""
    return _shapes.pad_to_shape(a, (rows,))
