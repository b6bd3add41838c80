"""The progress line of the Dask jobs (compress, learn)."""

import sys
import time


class ProgressLine:
    """One line on stderr, redrawn at most every 0.2 s (and at the end):
    `CAPTION [#####.....] DONE/TOTAL` then what suffix(done, elapsed_s, *info) returns.

    enabled: True draws the line, False nothing; a callable is called instead with
    (done, total, *info) after every update but the final one."""

    WIDTH = 30
    INTERVAL_S = 0.2

    def __init__(self, caption, total, enabled, suffix):
        self.caption, self.total, self.enabled, self.suffix = caption, total, enabled, suffix
        self.start, self.last = time.perf_counter(), 0.0

    def update(self, done, *info, final=False):
        if callable(self.enabled):
            if not final:
                self.enabled(done, self.total, *info)
            return
        if not self.enabled:
            return
        now = time.perf_counter()
        if not final and now - self.last < self.INTERVAL_S:
            return
        self.last = now
        filled = min(self.WIDTH, int(self.WIDTH * done / max(1, self.total)))
        sys.stderr.write(f"\r{self.caption} [{'#' * filled}{'.' * (self.WIDTH - filled)}] {done}/{self.total}"
                         + self.suffix(done, now - self.start, *info) + ("\n" if final else ""))
        sys.stderr.flush()
