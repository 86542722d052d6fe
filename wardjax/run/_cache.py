"""JAX's persistent compile cache, switched on by the processes wardjax starts (the CLI, cluster workers)."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["enable_compile_cache"]


def enable_compile_cache(cache_dir: Path | None) -> None:
    """Keep XLA's compiled programs on disk, so that a second run skips most compilation.

    Compiling the kernels costs tens of seconds per process; JAX's persistent
    cache makes that a one-time cost per machine and shape. Set here, in the
    command (the process is ours), never on import of the library.
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
        return
    import jax

    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
