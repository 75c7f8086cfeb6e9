"""An in-process HTTP server that speaks the part of Flamenco's REST API (v3) ``solver.farm.flamenco``
uses, and runs a tracking job's tasks itself, so the follow-up (submit, poll, re-submit) is tested
where Go is missing.

A submitted ``articula-track`` job becomes one task per chunk it runs (``chunk-NNNN frames A:B``) and a
``merge`` task, as ``addon/farm/job_types/articula_track.js`` makes them.  Tasks run in order when the
job is submitted: a chunk task calls ``track(job_number, chunk, settings)`` (the test's Worker: it
writes the chunk's bundle, or returns an error text: the task fails), the merge task runs the real
``solver.track.merge`` on the chunk bundles with the job's ``agree_mm``.  As on a Manager with fewer
than three Workers, a failed task fails the job and the tasks after it are cancelled."""
import json
import re
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from articula.solver.errors import ArticulaInputError
from articula.solver.farm import chunks as chunk_plan
from articula.solver.formats.bundle import save_bundle
from articula.solver.track import merge


class Farm:
    """The jobs (``submitted``: the bodies in order) and their tasks; ``track`` is the chunk Worker."""

    def __init__(self, track):
        self.track, self.submitted, self.jobs, self.logs = track, [], {}, {}
        self.lock = threading.Lock()

    def submit(self, body: dict) -> dict:
        with self.lock:
            self.submitted.append(body)
            job_id = f"job-{len(self.submitted)}"
            tasks = self._run(len(self.submitted), job_id, body["settings"])
            status = "failed" if any(t["status"] == "failed" for t in tasks) else "completed"
            self.jobs[job_id] = {"id": job_id, "name": body["name"], "status": status, "tasks": tasks}
            return {"id": job_id, "status": "queued"}

    def _run(self, number: int, job_id: str, settings: dict) -> list:
        ranges = chunk_plan.from_text(settings["chunks"])
        run = [int(k) for k in settings["run"].split(",")] if settings["run"] not in ("all", "none") else []
        steps = [(f"chunk-{k:04d} frames {a}:{b}", k) for k, (a, b) in enumerate(ranges) if k in run]
        steps.append(("merge", None))
        tasks, failed = [], False
        for i, (name, k) in enumerate(steps):
            task = {"id": f"{job_id}-task-{i}", "name": name, "status": "canceled"}
            tasks.append(task)
            if failed:
                continue
            error = self.track(number, k, settings) if k is not None else self._merge(settings, ranges)
            task["status"] = "failed" if error else "completed"
            self.logs[task["id"]] = error or "done"
            failed = bool(error)
        return tasks

    @staticmethod
    def _merge(settings: dict, ranges) -> str:
        paths = [f"{settings['work_dir']}/{chunk_plan.file_name(k, r)}" for k, r in enumerate(ranges)]
        try:
            merged = merge.merge_chunks(merge.load_chunks(paths), float(settings["agree_mm"]) or None)
            save_bundle(settings["out"], merged.model, merged.poses, merged.provenance)
        except (ArticulaInputError, OSError) as exc:
            return f"articula merge-tracks: error: {exc}"
        return ""


def _handler(farm: Farm):
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args):          # quiet
            pass

        def _answer(self, code: int, doc=None, text: str = None):
            raw = json.dumps(doc).encode() if doc is not None else (text or "").encode()
            self.send_response(code)
            self.send_header("Content-Type", "application/json" if doc is not None else "text/plain")
            self.send_header("Content-Length", str(len(raw)))
            self.end_headers()
            self.wfile.write(raw)

        def do_GET(self):
            path = self.path
            if path == "/api/v3/jobs/types":
                return self._answer(200, {"job_types": [{"name": "articula-track"}]})
            m = re.fullmatch(r"/api/v3/jobs/([\w-]+)(/tasks)?", path)
            if m and m.group(1) in farm.jobs:
                job = farm.jobs[m.group(1)]
                if m.group(2):
                    return self._answer(200, {"tasks": job["tasks"]})
                return self._answer(200, {k: job[k] for k in ("id", "name", "status")})
            m = re.fullmatch(r"/api/v3/tasks/([\w-]+)/logtail", path)
            if m and m.group(1) in farm.logs:
                return self._answer(200, text=farm.logs[m.group(1)])
            return self._answer(404, {"message": f"no such thing: {path}"})

        def do_POST(self):
            body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
            if self.path == "/api/v3/jobs":
                return self._answer(200, farm.submit(body))
            m = re.fullmatch(r"/api/v3/jobs/([\w-]+)/setstatus", self.path)
            if m and m.group(1) in farm.jobs:
                farm.jobs[m.group(1)]["status"] = "canceled"
                return self._answer(204)
            return self._answer(404, {"message": f"no such thing: {self.path}"})
    return Handler


class Server:
    """``with Server(farm) as url:`` a Manager for ``farm`` on a free port of 127.0.0.1."""

    def __init__(self, farm: Farm):
        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), _handler(farm))
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def __enter__(self) -> str:
        self.thread.start()
        return f"http://127.0.0.1:{self.httpd.server_address[1]}"

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()
