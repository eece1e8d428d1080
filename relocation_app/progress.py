"""Progress on stderr for the CLI, the demo and the evaluation sweep: a tqdm bar on a terminal; otherwise (a CI
or launch log, a pipe) a plain line at most every LOG_INTERVAL_S seconds and one when done, never a line per
update."""
from __future__ import annotations

import sys
import time
from typing import Any, TextIO

LOG_INTERVAL_S = 5.0


class Progress:
    """`update(n=..., desc=..., postfix=...)` with the absolute count (or `advance`), `close()` at the end."""

    def __init__(self, desc: str, unit: str, total: int | None = None, initial: int = 0, file: TextIO | None = None,
                 interval: float = LOG_INTERVAL_S, leave: bool = True) -> None:
        """A bar when `file` (stderr by default) is a terminal, else periodic lines `interval` s apart."""
        self.file = file if file is not None else sys.stderr
        self.desc, self.unit, self.total, self.n, self.postfix = desc, unit, total, initial, ""
        self.interval = interval
        self._t0 = self._said_at = time.monotonic()
        self._said: tuple[Any, ...] | None = None
        self._bar = None
        isatty = getattr(self.file, "isatty", None)
        if isatty is not None and isatty():
            from tqdm import tqdm
            self._bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, file=self.file, leave=leave,
                             dynamic_ncols=True)

    def update(self, n: int | None = None, *, advance: int = 0, desc: str | None = None,
               postfix: str | None = None) -> None:
        """Set the count to `n` (or add `advance`), the description and the text after the count."""
        self.n = (self.n if n is None else n) + advance
        self.desc = self.desc if desc is None else desc
        self.postfix = self.postfix if postfix is None else postfix
        if self._bar is not None:
            self._bar.set_description(self.desc, refresh=False)
            self._bar.set_postfix_str(self.postfix, refresh=False)
            self._bar.update(self.n - self._bar.n)
            return
        if time.monotonic() - self._said_at >= self.interval:
            self._line()

    def close(self) -> None:
        """The bar closed, or the last state as one line (unless it was the last line already)."""
        if self._bar is not None:
            self._bar.close()
        elif self._said != self._state():
            self._line()

    def _state(self) -> tuple[Any, ...]:
        return self.desc, self.n, self.postfix

    def _line(self) -> None:
        now = time.monotonic()
        count = f"{self.n}/{self.total}" if self.total is not None else f"{self.n}"
        tail = f" {self.postfix}" if self.postfix else ""
        print(f"{self.desc}: {count} {self.unit}{tail} ({now - self._t0:.0f} s)", file=self.file, flush=True)
        self._said_at, self._said = now, self._state()
