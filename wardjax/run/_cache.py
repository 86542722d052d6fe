"""JAX's persistent compile cache, switched on by the processes wardjax starts (the CLI, cluster workers)."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["MAX_BYTES", "enable_compile_cache"]

MAX_BYTES = 4 << 30  # the compile cache's size limit (4 GiB), which also turns on JAX's file lock


def enable_compile_cache(cache_dir: Path | None) -> None:
    """Keep XLA's compiled programs on disk, so that a second run skips most compilation.

    Compiling the kernels costs tens of seconds per process; JAX's persistent
    cache makes that a one-time cost per machine and shape. Set here, in the
    command (the process is ours), never on import of the library.

    The cache has a size limit (:data:`MAX_BYTES`, least recently used
    entries go first): with one, JAX reads and writes it under a file lock
    (``filelock``), so processes sharing it — the workers of ``wardjax fit
    --scheduler`` — never read an entry another is still writing.
    """
    import os

    import platformdirs

    path = Path(cache_dir) if cache_dir else Path(platformdirs.user_cache_dir("wardjax")) / "xla"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return  # a read-only home: run without the cache rather than fail
    if "jax" not in sys.modules:  # JAX reads these when it is imported: a command that never needs it never pays for it
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(path)
        os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
        os.environ["JAX_COMPILATION_CACHE_MAX_SIZE"] = str(MAX_BYTES)
        return
    import jax

    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
