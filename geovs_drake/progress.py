"""Progress on stderr: a tqdm bar on a terminal, sparse plain lines otherwise.

Why not tqdm everywhere: written to a file or a CI log, its carriage returns
pile up into one enormous line, and a float total shows drift such as
``6.599999999999998/30.0``. Here counts are integers, and off a terminal a
line is printed at most every few seconds, and always at the end.

``delay_s`` keeps short work quiet: nothing is shown until that much wall
time has passed (tqdm's own ``delay`` on a terminal), so ``simulate``, whose
default run takes well under a second, prints progress only on long runs.
"""

from __future__ import annotations

import sys
import time

__all__ = ["HorizonProgress", "Progress"]


class Progress:
    """Count ``total`` integer units of work, reported on stderr.

    Args:
        total: the units to do (e.g. starts, or percent of a simulated horizon).
        unit: their name, for the report.
        description: what is being done, e.g. ``"geovs-drake sweep"``.
        min_interval_s: off a terminal, the least time between two lines.
        delay_s: wall time [s] before anything is shown; work that ends sooner
            prints nothing at all.
    """

    #: tqdm's ``bar_format`` on a terminal; None: tqdm's own, which shows the count.
    bar_format: str | None = None

    def __init__(
        self,
        total: int,
        unit: str,
        description: str,
        min_interval_s: float = 2.0,
        delay_s: float = 0.0,
    ) -> None:
        self.total, self.unit, self.description = int(total), unit, description
        self.done = 0
        self.min_interval_s = min_interval_s
        self.delay_s = delay_s
        self._start = time.perf_counter()
        self._last_line = -float("inf")
        self._printed = False
        self._bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm  # a core dependency, imported only for a terminal

            self._bar = tqdm(
                total=self.total,
                unit=unit,
                desc=description,
                file=sys.stderr,
                leave=False,
                delay=delay_s,
                bar_format=self.bar_format,
            )

    def update_to(self, done: int) -> None:
        """Report that ``done`` units (an integer, not decreasing) are finished."""
        done = min(int(done), self.total)
        if done <= self.done:
            return
        if self._bar is not None:
            self._bar.update(done - self.done)
        self.done = done
        if self._bar is None:
            now = time.perf_counter()
            if now - self._start < self.delay_s:
                return
            # The last line only closes a report that was started: after the delay
            # a first line is due at once.
            if now - self._last_line >= self.min_interval_s or (
                done == self.total and self._printed
            ):
                self._last_line, self._printed = now, True
                print(
                    f"{self.description}: {self.amount(done)} after {now - self._start:.1f} s",
                    file=sys.stderr,
                    flush=True,
                )

    def amount(self, done: int) -> str:
        """``done`` units as a line shows them: a count of the total, ``5/30 starts``."""
        return f"{done}/{self.total} {self.unit}"

    def update(self, units: int) -> None:
        """Report ``units`` more finished units."""
        self.update_to(self.done + units)

    def close(self) -> None:
        """Close the terminal's bar, if any (plain lines need nothing)."""
        if self._bar is not None:
            self._bar.close()


class HorizonProgress(Progress):
    """Percent of a simulated horizon, in whole percents (a line reads ``66 % of 30 s
    simulated after 3.0 s``); call it with the simulated time.

    It is the ``progress`` callback of :func:`geovs_drake.simulation.simulate`.
    """

    #: On a terminal, the percentage and the bar, without tqdm's count ``66/100``.
    bar_format = "{l_bar}{bar}| [{elapsed}<{remaining}]"

    def __init__(
        self,
        horizon_s: float,
        description: str,
        min_interval_s: float = 2.0,
        delay_s: float = 0.0,
    ) -> None:
        super().__init__(100, "%", description, min_interval_s=min_interval_s, delay_s=delay_s)
        self.horizon_s = horizon_s

    def amount(self, done: int) -> str:
        """``done`` percent as a share of the horizon, ``66 % of 30 s simulated``: a
        percentage is no count of 100 (the line read ``66/100 %``)."""
        return f"{done} % of {self.horizon_s:g} s simulated"

    def __call__(self, t: float) -> None:
        # Whole percents: a float total shows rounding drift such as 6.599999999999998/30.0.
        self.update_to(int(100 * t / self.horizon_s + 1e-9))
