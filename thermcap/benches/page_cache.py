"""Page cache the host must back again, kept out of what a benchmark times.

Why: on a virtual machine whose balloon device reports free pages to the host (virtio-balloon
free page reporting, on in the machines this project is measured on), memory that has stayed
free for about two seconds is handed back, and the host faults it in again on its next use. A
benchmark deletes what it wrote, so most of the machine's memory is free, and a run that writes
its output after a pause fills the page cache from such memory: here the first 256 MB written
in a process cost 1.1-1.7 s of kernel CPU, the same 256 MB written again 0.06 s. At 320x256 that
moved the recorder's CPU per frame by 0.1 ms between two runs of the same code, more than the gap
it is compared on. A server that archives all day has no such cost: its page cache is full, and
new writes reuse pages the host already backs.

So, right before a timed run, a benchmark writes and deletes a file about as large as the run's
output, in the folder the run writes to (``prime``). The run's writes then land on pages just
freed, which the host still backs. Both sides of a comparison are primed alike.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

__all__ = ["prime"]

_BLOCK = b"\xa5" * (4 << 20)


def prime(directory: Path | str, nbytes: int) -> float:
    """Write and delete about ``nbytes`` in ``directory``; returns the CPU seconds it took (the
    cost the timed run no longer pays, or next to nothing when the pages were backed already)."""
    path = Path(directory) / f".prime-{os.getpid()}"
    cpu = time.process_time()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        written = 0
        while written < nbytes:
            written += os.write(fd, _BLOCK[:min(len(_BLOCK), nbytes - written)])
    finally:
        os.close(fd)
        path.unlink(missing_ok=True)
    return time.process_time() - cpu
