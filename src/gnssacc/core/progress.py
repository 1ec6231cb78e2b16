"""Progress bars: shown on a terminal, silent when stderr is not a TTY (CI, pipes, notebooks);
a campaign also has plain lines for logs."""

from __future__ import annotations

import sys
import time


def _tqdm():
    """tqdm's bar class, imported when a bar is first made: the import takes a twentieth of a
    second, which a run whose stderr is not a terminal (no bar) does not pay."""
    from tqdm import tqdm

    return tqdm


def progress(iterable, desc: str = "", enable: bool = True, total: int | None = None):
    """Wrap ``iterable`` in a tqdm bar when ``enable`` and stderr is a terminal; otherwise
    ``iterable`` itself."""
    if not (enable and sys.stderr.isatty()):
        return iterable
    return _tqdm()(iterable, desc=desc, total=total, leave=False, dynamic_ncols=True)


class StageProgress:
    """Stages of a long preparation, said as each starts, on stderr: a bar on a terminal;
    otherwise (``lines``) one plain line per stage, ``gnssacc: preparing: noise identification
    (3 of 3) ...``.

    Parameters
    ----------
    total : int
        Stages expected.
    lines : bool
        Print the plain lines when stderr is not a terminal.
    enable : bool
        Show anything at all.
    """

    def __init__(self, total: int, lines: bool = True, enable: bool = True):
        self.total, self.k = total, 0
        self.tty = sys.stderr.isatty()
        self.lines = enable and lines and not self.tty
        self.bar = (
            _tqdm()(total=total, desc="preparing", leave=False, dynamic_ncols=True)
            if enable and self.tty
            else None
        )

    def __call__(self, stage: str) -> None:
        """Stage ``stage`` (a few words) starts."""
        if self.bar is not None:
            self.bar.update(min(self.k, self.total) - self.bar.n)
            self.bar.set_description_str(f"preparing: {stage}", refresh=True)
        elif self.lines:
            print(
                f"gnssacc: preparing: {stage} ({self.k + 1} of {self.total}) ...",
                file=sys.stderr,
                flush=True,
            )
        self.k += 1

    def close(self) -> None:
        """The preparation is over: the bar goes."""
        if self.bar is not None:
            self.bar.close()


class CampaignProgress:
    """A campaign's progress: one bar on a terminal (tasks done, failed, running, ETA), otherwise
    one plain line per finished task (when ``lines``), on stderr.

    Parameters
    ----------
    total : int
        Tasks in the campaign.
    done, failed : int
        Tasks already finished (of them failed) before this run.
    lines : bool
        Print the plain lines when stderr is not a terminal.
    """

    def __init__(self, total: int, done: int = 0, failed: int = 0, lines: bool = True):
        self.total, self.done, self.failed, self.lines = total, done, failed, lines
        self.tty = sys.stderr.isatty()
        self.bar = _tqdm()(
            total=total,
            initial=done,
            desc="campaign",
            unit="task",
            disable=not self.tty,
            leave=False,
            dynamic_ncols=True,
        )
        self.t0 = time.monotonic()
        self.ran = 0

    def _say(self, text: str) -> None:
        if self.lines and not self.tty:
            print(f"gnssacc: batch: {text}", file=sys.stderr, flush=True)

    def started(self, where: str, running: int) -> None:
        """The executor is up (``where`` it runs) and ``running`` tasks have started."""
        self.t0 = time.monotonic()
        self._say(
            f"{self.total - self.done} of {self.total} tasks to run on {where} ({self.done} finished before)"
        )
        self._postfix(running)

    def update(
        self, label: str, ok: bool, seconds: float, running: int, error: str | None = None
    ) -> None:
        """Task ``label`` finished (``ok`` or failed with ``error``) after ``seconds``."""
        self.done += 1
        self.ran += 1
        self.failed += not ok
        self.bar.update(1)
        self._postfix(running)
        left = self.total - self.done
        eta = (time.monotonic() - self.t0) / self.ran * left
        self._say(
            f"[{self.done}/{self.total}] {label}: {'ok' if ok else 'failed: ' + str(error)} ({seconds:.1f} s); "
            f"{self.failed} failed, {running} running, ETA {eta:.0f} s"
        )

    def _postfix(self, running: int) -> None:
        self.bar.set_postfix_str(f"failed {self.failed}, running {running}", refresh=True)

    def close(self) -> None:
        self.bar.close()
