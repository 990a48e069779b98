"""The script's progress on stderr: a bar on a terminal, else a line per tenth of each object."""

import sys
import time


class Progress:
    """Progress of the bake on stderr: a bar on a terminal, else a line at each tenth ("Ground: 30%").

    The first line of each object comes with its first traced rays: a log shows when the tracing
    began, and a test can wait for it. Called on the main thread, from the bake's messages.
    """

    def __init__(self, stream=sys.stderr, enabled=True, width=30):
        self.stream = stream
        self.enabled = enabled
        self.tty = enabled and stream.isatty()
        self.width = width
        self.label = ""
        self.shown = 0.0
        self.tenth = None
        self.start = time.monotonic()

    def begin(self, label):
        self.label = label
        self.tenth = None
        self.start = time.monotonic()
        if self.tty:
            self._draw(0.0)

    def update(self, fraction):
        if not self.enabled:
            return
        fraction = min(max(fraction, 0.0), 1.0)
        if self.tty:
            now = time.monotonic()
            if fraction >= 1.0 or now - self.shown >= 0.1:  # drawing only: the bake does not wait
                self._draw(fraction)
            return
        tenth = int(fraction * 10)
        if self.tenth is None or tenth > self.tenth:
            self.tenth = tenth
            print(f"bake_ao: {self.label}: {tenth * 10}%", file=self.stream, flush=True)

    def _draw(self, fraction):
        now = time.monotonic()
        self.shown = now
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {fraction:4.0%} {now - self.start:6.1f} s")
        self.stream.flush()

    def end(self):
        if self.tty:
            self.stream.write("\r" + " " * (len(self.label) + self.width + 20) + "\r")
            self.stream.flush()
