"""Progress per stage on stderr: a spinner while a stage runs, one line with its time when it ends.

A long command (``wardjax diagnose``, ``report``, ``fit``) says what it is
doing: each stage is announced by :meth:`Stages.advance` (or by
:func:`stage` from code deeper in the run layer, which reaches the
:class:`Stages` the command opened), shown with a spinner while it runs, and
printed as one line with its wall time when the next begins, the time JAX
spent compiling in it named apart (the first call of each kernel shape).

Off when stderr is not a terminal (a pipe, a log file, a test), unless asked
for (``enabled=True``, the commands' ``--progress``); then the lines are
printed without the spinner. Nothing is printed on stdout.
"""

from __future__ import annotations

import contextvars
import time
from collections.abc import Callable

from rich.console import Console
from rich.markup import escape

__all__ = ["Stages", "stage"]

_current: contextvars.ContextVar[Callable[[str], None] | None] = contextvars.ContextVar("wardjax_stage", default=None)

# Seconds JAX spent tracing, lowering and compiling since the listener was registered (one listener per process).
_compile_seconds = [0.0]
_listening = [False]


def _listen_to_compiles() -> None:
    if _listening[0]:
        return
    import jax

    def on_duration(event: str, duration_secs: float, **_: str | int) -> None:
        if event.startswith("/jax/core/compile/"):
            _compile_seconds[0] += duration_secs

    jax.monitoring.register_event_duration_secs_listener(on_duration)
    _listening[0] = True


def stage(name: str) -> None:
    """Announce that stage ``name`` begins, to the :class:`Stages` the running command opened (else nothing)."""
    advance = _current.get()
    if advance is not None:
        advance(name)


class Stages:
    """The stages of one command, shown on ``console`` (stderr by default).

    Parameters
    ----------
    enabled
        ``None`` (default): when ``console`` is a terminal. ``True``: always
        (without the spinner where not a terminal); ``False``: never.
    console
        Where the lines go; default a rich console on stderr.
    compiles
        Name the seconds JAX spent compiling in each stage.
    on_begin
        Called with each stage's name as it begins, instead of the spinner
        (for a caller that already draws a live display, such as a progress bar).
    """

    def __init__(
        self,
        enabled: bool | None = None,
        console: Console | None = None,
        *,
        compiles: bool = True,
        on_begin: Callable[[str], None] | None = None,
    ) -> None:
        self.console = console or Console(stderr=True, emoji=False)
        self.enabled = self.console.is_terminal if enabled is None else enabled
        self.compiles = compiles
        self.on_begin = on_begin
        self._name: str | None = None
        self._t0 = 0.0
        self._c0 = 0.0
        self._status = None
        self._token = None

    def __enter__(self) -> Stages:
        if self.enabled:
            if self.compiles:
                _listen_to_compiles()
            if self.console.is_terminal and self.on_begin is None:
                self._status = self.console.status("", spinner="dots")
                self._status.start()
        self._token = _current.set(self.advance)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._end(failed=exc_type is not None)
        if self._status is not None:
            self._status.stop()
        if self._token is not None:
            _current.reset(self._token)

    def advance(self, name: str) -> None:
        """End the current stage (its line printed) and begin ``name``."""
        self._end()
        self._name, self._t0, self._c0 = name, time.perf_counter(), _compile_seconds[0]
        if self._status is not None:
            self._status.update(escape(f"{name} …"))
        if self.on_begin is not None:
            self.on_begin(name)

    def fail(self) -> None:
        """End the current stage as failed (its line marked ✗)."""
        self._end(failed=True)

    def _end(self, failed: bool = False) -> None:
        if self._name is None or not self.enabled:
            self._name = None
            return
        seconds = time.perf_counter() - self._t0
        compiled = _compile_seconds[0] - self._c0
        extra = f", of which compiling {compiled:.1f} s" if self.compiles and compiled >= 0.05 else ""
        mark = "[red]✗[/]" if failed else "[green]✓[/]"
        self.console.print(f"{mark} {escape(self._name)} ({seconds:.1f} s{extra})", highlight=False, soft_wrap=True)
        self._name = None
