"""One matex run as a child process, read through its progress stream (`--progress json`,
README "Progress stream"). No bpy here: the operators poll a MatexRun from Blender's timer, so
Blender never waits on the process."""

import json
import os
import queue
import shutil
import signal
import subprocess
import threading


class MatexRun:
    """Starts `matex ARGS --progress json` and collects its events.

    A reader thread turns each stdout line into a dict and queues it; poll() hands the new ones
    to the caller (Blender's main thread). The last event is the result line
    ({"event": "result", "ok": ..., "exit": ..., "out"/"error": ...}); when matex dies without
    one (a crash, a kill), a result is made from its exit status and the last stderr line."""

    def __init__(self, argv):
        self.argv = list(argv) + ["--progress", "json"]
        self.events = queue.Queue()
        self.stderr_tail = []
        self.result = None
        self.cancelled = False
        self.proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, encoding="utf-8", errors="replace")
        self._threads = [threading.Thread(target=self._read_stdout, daemon=True),
                         threading.Thread(target=self._read_stderr, daemon=True)]
        for t in self._threads:
            t.start()

    def _read_stdout(self):
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue  # not part of the stream (there is none such today; never fatal)
            if isinstance(event, dict):
                self.events.put(event)

    def _read_stderr(self):
        for line in self.proc.stderr:
            self.stderr_tail = (self.stderr_tail + [line.rstrip("\n")])[-20:]

    def poll(self):
        """The events that arrived since the last call; sets self.result once the process has
        ended and both its streams are read to the end."""
        finished = self.proc.poll() is not None
        if finished:
            for t in self._threads:
                t.join(timeout=5)
        out = drain_events(self)
        if finished and self.result is None:
            self.result = self._result_without_line()
        return out

    def _result_without_line(self):
        code = self.proc.returncode
        last = next((l for l in reversed(self.stderr_tail) if l.strip()), "")
        return {"event": "result", "ok": False, "exit": code if code >= 0 else 128 - code,
                "error": last or "matex ended with status %d and no message" % code}

    def done(self):
        return self.result is not None

    def cancel(self):
        """SIGINT, as Ctrl-C: matex stops after the current step, removes its staging folder,
        writes nothing and ends with exit 130."""
        if self.proc.poll() is None and not self.cancelled:
            self.cancelled = True
            self.proc.send_signal(signal.SIGINT)

    def wait(self, timeout=None):
        self.proc.wait(timeout=timeout)
        return self.poll()


def drain_events(run):
    """The events a run's reader threads queued since the last call; the result line, when among
    them, is kept as run.result (MatexRun and server.ServerRun share this)."""
    out = []
    while not run.events.empty():
        event = run.events.get_nowait()
        out.append(event)
        if event.get("event") == "result":
            run.result = event
    return out


def progress_fraction(event):
    """0..1 over the run from one event: views done out of the budget, the current view's
    denoising steps counting as a share of the next view."""
    total = max(1, int(event.get("views_total", 1)))
    done = float(event.get("views_done", 0))
    steps = int(event.get("steps", 0))
    if steps > 0:
        done += float(event.get("step", 0)) / steps
    return max(0.0, min(1.0, done / total))


def describe(event):
    """A short status-bar line for one event."""
    if event.get("event") == "step":
        return "matex: %s, step %d/%d" % (event.get("stage", ""), event.get("step", 0), event.get("steps", 0))
    return "matex: %s" % event.get("message", event.get("stage", ""))


def find_matex(preferred):
    """The matex executable: the add-on preference when set, else `matex` on PATH."""
    if preferred:
        path = os.path.abspath(os.path.expanduser(preferred))
        return path if os.path.isfile(path) and os.access(path, os.X_OK) else None
    return shutil.which("matex")
