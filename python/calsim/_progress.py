"""Progress of a running command: a tqdm bar (in a notebook, tqdm's widget) when tqdm is
installed, else one line per finished stage on standard error, or the caller's own callable.

The native code calls ``callback(event, text, done, total)`` from its worker threads, at most ten
times a second per stage: ``event`` is ``started`` (``text`` the command's start line),
``progress`` (``done`` of ``total`` items of the stage ``text``: identifications, work units,
realisations), ``stage_done`` or ``warning`` (``text`` the warning).
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

Callback = Callable[[str, str, int, int], object]
Progress = bool | Callback | None


@contextmanager
def observer(progress: Progress) -> Iterator[Callback | None]:
    """The callback for ``progress``: None (quiet) for False or None, the callable itself, or
    :class:`Bars` for True (closed when the command ends, also on an error)."""
    if progress is None or progress is False:
        yield None
    elif progress is True:
        bars = Bars()
        try:
            yield bars
        finally:
            bars.close()
    elif callable(progress):
        yield progress
    else:
        raise TypeError(f"progress: {progress!r}: True, False or a callable f(event, text, done, total)")


class Bars:
    """Shows a command's progress: a tqdm bar per stage (``tqdm.auto``: a widget in a notebook),
    or without tqdm the start line and one line per finished stage on standard error."""

    def __init__(self, file: TextIO | None = None) -> None:
        self._tqdm: Any
        try:
            from tqdm.auto import tqdm  # type: ignore[import-untyped, unused-ignore]

            self._tqdm = tqdm
        except ImportError:
            self._tqdm = None
        self._file: TextIO = file or sys.stderr
        self._bar: Any = None
        self._last: tuple[str, int, int] | None = None
        self._lock = threading.Lock()

    def __call__(self, event: str, text: str, done: int, total: int) -> None:
        with self._lock:
            if event == "started":
                print(text, file=self._file, flush=True)
            elif event == "progress":
                self._progress(text, done, total)
            elif event in ("stage_done", "warning"):
                self._end_stage()

    def _progress(self, what: str, done: int, total: int) -> None:
        self._last = (what, done, total)
        if self._tqdm is None:
            return
        if self._bar is None:
            self._bar = self._tqdm(total=total, desc=what, file=self._file, leave=False)
        self._bar.total = total
        self._bar.n = done
        self._bar.refresh()

    def _end_stage(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self._last is not None:
            what, done, total = self._last
            print(f"{done}/{total} {what}", file=self._file, flush=True)
            self._last = None

    def close(self) -> None:
        """Ends the bar of a stage left open (a command that stopped on an error)."""
        with self._lock:
            self._end_stage()
