"""Output folders for calls that write a run folder and read their results back."""

import os
import tempfile
from pathlib import Path
from typing import Optional, Union


class Scratch:
    """An output folder for a call: ``out`` if given (kept), else a temporary one removed once
    the results are read."""

    def __init__(self, out: Optional[Union[str, "os.PathLike[str]"]]):
        self._tmp = None if out is not None else tempfile.TemporaryDirectory(prefix="femu-")
        self.path = Path(out) if out is not None else Path(self._tmp.name)

    def __enter__(self) -> Path:
        return self.path

    def __exit__(self, *exc) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
