"""What a long femu call shows while it runs: its notes (a finished stage's numbers) and its
tasks as progress bars — tqdm's (``tqdm.auto``: widgets in a notebook, text on a terminal) when
tqdm is installed, one line per task otherwise. The extension calls these methods from the
thread that called femu, between units of work (see ``crates/femu-py/src/running.rs``)."""

import sys
from typing import Any, Dict, Optional


class Reporter:
    """Shows femu's progress. ``notes``: print the notes (warnings are always printed, as the
    command line prints them also with ``--quiet``); ``bars``: draw the tasks."""

    def __init__(self, notes: bool = True, bars: bool = True, stream=None):
        self.notes = notes
        self.stream = stream
        self._bars: Dict[int, Any] = {}
        self._tqdm = None
        if bars:
            try:
                from tqdm.auto import tqdm

                self._tqdm = tqdm
            except ImportError:
                self._tqdm = None
        self._plain = bars and self._tqdm is None

    def _print(self, line: str) -> None:
        stream = self.stream or sys.stdout
        if self._tqdm is not None and self._bars:
            self._tqdm.write(line, file=stream)
        else:
            print(line, file=stream, flush=True)

    def note(self, line: str) -> None:
        if self.notes:
            self._print(line)

    def warn(self, line: str) -> None:
        self._print(f"warning: {line}")

    def start(self, task: int, what: str, total: Optional[int]) -> None:
        if self._tqdm is not None:
            self._bars[task] = self._tqdm(total=total, desc=what, leave=False)
        elif self._plain and self.notes:
            self._print(f"{what} ...")

    def inc(self, task: int, n: int) -> None:
        bar = self._bars.get(task)
        if bar is not None:
            bar.update(n)

    def message(self, task: int, text: str) -> None:
        bar = self._bars.get(task)
        if bar is not None:
            bar.set_postfix_str(text, refresh=True)

    def end(self, task: int) -> None:
        bar = self._bars.pop(task, None)
        if bar is not None:
            bar.close()

    def close(self) -> None:
        for task in list(self._bars):
            self.end(task)


def reporter(progress: Any) -> Optional[Any]:
    """The reporter of a call's ``progress`` argument: ``True`` notes and bars, ``"bars"``
    bars only, ``False``/``None`` nothing (warnings still), or an object with the methods of
    :class:`Reporter`."""
    if progress is True:
        return Reporter()
    if progress == "bars":
        return Reporter(notes=False)
    if progress is False or progress is None:
        return Reporter(notes=False, bars=False)
    return progress
