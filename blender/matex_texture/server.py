"""One texturing job on a running `matex serve` (docs/SERVE.md), with the interface of
stream.MatexRun (poll, done, result, cancel), so that job.Job drives either. No bpy here.

The job is posted (multipart: mesh, options, style_image), a reader thread follows its event
stream (GET /v1/jobs/ID/events) and queues each `progress` event as matex's own stream has it;
at the `end` event the output files are downloaded into the job's folder, a result line is made
as matex's (`{"event": "result", "ok", "out" | "error", ...}`) and the job is removed from the
server. cancel() is DELETE /v1/jobs/ID: the server stops the job after its current step."""

import json
import os
import queue
import shlex
import threading
import urllib.error
import urllib.request
import uuid

from .stream import drain_events

TIMEOUT = 30  # seconds for one request; the event stream sends keep-alives well within it


def options(s, extra_args):
    """The options part: the panel's fields as job keys, then the artist's extra options
    ("--candidates 20 --geometric-normals" -> {"candidates": "20", "geometric-normals": true})."""
    o = {"prompt": s.prompt, "seed": s.seed, "views": s.views, "texture-size": s.texture_size, "up": "z"}
    if s.fast:
        o["fast"] = True
    if s.steps > 0:
        o["steps"] = s.steps
    if s.negative:
        o["negative"] = s.negative
    if s.style_image:
        o["style-scale"] = s.style_scale
    words = shlex.split(extra_args)
    i = 0
    while i < len(words):
        key = words[i].lstrip("-")
        if i + 1 < len(words) and not words[i + 1].startswith("--"):
            o[key] = words[i + 1]
            i += 2
        else:
            o[key] = True
            i += 1
    return o


def _multipart(fields):
    """fields: (name, filename or None, bytes) -> (body, content type)."""
    boundary = "matex-" + uuid.uuid4().hex
    parts = []
    for name, filename, data in fields:
        head = 'Content-Disposition: form-data; name="%s"' % name
        if filename:
            head += '; filename="%s"' % os.path.basename(filename).replace('"', "")
        parts.append(b"--" + boundary.encode() + b"\r\n" + head.encode() + b"\r\n\r\n" + data + b"\r\n")
    return b"".join(parts) + b"--" + boundary.encode() + b"--\r\n", "multipart/form-data; boundary=" + boundary


def _error_of(e):
    """The server's message of an HTTP error ({"error": {"message"}}), else the error itself."""
    try:
        return "matex server: %s" % json.loads(e.read().decode("utf-8"))["error"]["message"]
    except Exception:
        return "matex server: %s" % e


class ServerRun:
    def __init__(self, url, token, mesh_path, opts, style_images, out_dir):
        self.url, self.token, self.out = url.rstrip("/"), token, out_dir
        self.events = queue.Queue()
        self.result = None
        self.cancelled = False
        fields = [("mesh", mesh_path, open(mesh_path, "rb").read()),
                  ("options", None, json.dumps(opts).encode("utf-8"))]
        fields += [("style_image", p, open(p, "rb").read()) for p in style_images]
        body, ctype = _multipart(fields)
        try:
            answer = self._request("POST", "/v1/jobs", body, {"Content-Type": ctype})
        except urllib.error.HTTPError as e:
            raise ValueError(_error_of(e))
        except OSError as e:
            raise ValueError("matex server %s: %s" % (self.url, e))
        self.id = json.loads(answer.read().decode("utf-8"))["id"]
        self._thread = threading.Thread(target=self._follow, daemon=True)
        self._thread.start()

    def _request(self, method, path, body=None, headers=None):
        req = urllib.request.Request(self.url + path, data=body, method=method, headers=dict(headers or {}))
        if self.token:
            req.add_header("Authorization", "Bearer " + self.token)
        return urllib.request.urlopen(req, timeout=TIMEOUT)

    def _follow(self):
        try:
            end = None
            with self._request("GET", "/v1/jobs/%s/events" % self.id) as stream:
                kind = None
                for raw in stream:
                    line = raw.decode("utf-8").rstrip("\r\n")
                    if line.startswith("event: "):
                        kind = line[7:]
                    elif line.startswith("data: ") and kind == "progress":
                        self.events.put(json.loads(line[6:]))
                    elif line.startswith("data: ") and kind == "end":
                        end = json.loads(line[6:])
            self.events.put(self._finish(end))
        except (OSError, ValueError) as e:
            self.events.put({"event": "result", "ok": False, "exit": 1, "error": "matex server: %s" % e})

    def _finish(self, end):
        """The result line of the ended job; its files downloaded when it is done."""
        if end is None:
            return {"event": "result", "ok": False, "exit": 1, "error": "matex server: the event stream ended early"}
        state = end.get("state")
        if state != "done":
            self._request("DELETE", "/v1/jobs/%s" % self.id).read()
            return {"event": "result", "ok": False, "exit": 130 if state == "cancelled" else 1,
                    "error": end.get("error", "the job was %s" % state)}
        os.makedirs(self.out, exist_ok=True)
        for name in end.get("files", []):
            with self._request("GET", "/v1/jobs/%s/files/%s" % (self.id, name)) as r, \
                    open(os.path.join(self.out, os.path.basename(name)), "wb") as f:
                f.write(r.read())
        self._request("DELETE", "/v1/jobs/%s" % self.id).read()
        progress = end.get("progress") or {}
        return {"event": "result", "ok": True, "exit": 0, "out": self.out,
                "coverage": progress.get("coverage", 0.0), "seconds": progress.get("seconds", 0.0)}

    def poll(self):
        return drain_events(self)

    def done(self):
        return self.result is not None

    def cancel(self):
        if not self.cancelled and self.result is None:
            self.cancelled = True
            try:
                self._request("DELETE", "/v1/jobs/%s" % self.id).read()
            except OSError:
                pass  # the stream's end reports what happened

    def wait(self, timeout=None):
        self._thread.join(timeout)
        return self.poll()
