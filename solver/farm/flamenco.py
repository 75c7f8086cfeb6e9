"""A Flamenco Manager's REST API (v3) over plain HTTP (urllib): submit a job, follow it and its tasks,
cancel it.  Flamenco is a separate program (GPL-3) reached over the network; nothing of it is linked or
bundled.  Every failure becomes a :class:`FarmError` that says what to check."""
from __future__ import annotations

import json
import platform as host
import socket
import urllib.error
import urllib.parse
import urllib.request

from ..errors import ArticulaInputError

TIMEOUT = 10.0                       # seconds per request
FINISHED = ("completed", "failed", "canceled")


class FarmError(ArticulaInputError):
    """The Manager cannot be reached or refused a request."""


def submitter_platform() -> str:
    """Flamenco's platform name of this machine ("linux", "windows", "darwin"): the Manager maps the
    job's paths through its two-way variables from this platform to each Worker's."""
    return {"Windows": "windows", "Darwin": "darwin"}.get(host.system(), "linux")


class Manager:
    """One Manager at ``url`` (e.g. ``http://farm:8080``); ``platform``: the submitter's platform name for
    the two-way variables (default: this machine's, :func:`submitter_platform`)."""

    def __init__(self, url: str, timeout: float = TIMEOUT, platform: str = ""):
        url = str(url or "").strip().rstrip("/")
        if not url:
            raise FarmError("no Flamenco Manager URL given (e.g. http://localhost:8080)")
        if "://" not in url:
            url = "http://" + url
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise FarmError(f"{url}: not a Manager URL (expected http://HOST:PORT)")
        self.url, self.timeout = url, float(timeout)
        self.platform = platform or submitter_platform()

    def request(self, method: str, path: str, body=None):
        """The answer of ``method path``: decoded JSON, text for a text answer, None when empty."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method,
                                     headers={"Content-Type": "application/json", "Accept": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as resp:
                raw, kind = resp.read(), resp.headers.get_content_type()
        except urllib.error.HTTPError as exc:
            raise FarmError(f"Flamenco Manager {self.url}: {method} {path} refused ({exc.code}: "
                            f"{_error_text(exc)})") from None
        except (urllib.error.URLError, socket.timeout, ConnectionError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            raise FarmError(f"Flamenco Manager {self.url} unreachable ({reason}); is it running, and is the URL "
                            f"right?") from None
        if not raw.strip():
            return None
        return json.loads(raw) if kind == "application/json" else raw.decode("utf-8", "replace")

    def version(self) -> dict:
        return self.request("GET", "/api/v3/version")

    def job_type_names(self) -> list:
        return [t["name"] for t in self.request("GET", "/api/v3/jobs/types").get("job_types", [])]

    def require_job_type(self, name: str) -> None:
        """Raise, naming the folder to copy the job types to, unless the Manager knows ``name``."""
        if name not in self.job_type_names():
            raise FarmError(f"the Flamenco Manager {self.url} has no job type {name!r}: write Articula's job types "
                            f"into the 'scripts' folder beside the flamenco-manager executable "
                            f"(./run farm job-types --to <that folder>/scripts) and restart the Manager")

    def submit(self, job: dict) -> dict:
        """Submit ``job`` (name, type, settings, metadata, priority); returns the Manager's job record
        (``id``, ``status``...)."""
        body = {"priority": 50, "metadata": {}, "submitter_platform": self.platform, **job}
        return self.request("POST", "/api/v3/jobs", body)

    def job(self, job_id: str) -> dict:
        return self.request("GET", f"/api/v3/jobs/{job_id}")

    def tasks(self, job_id: str) -> list:
        """The job's tasks (``id``, ``name``, ``status``...)."""
        return self.request("GET", f"/api/v3/jobs/{job_id}/tasks").get("tasks", [])

    def log_tail(self, task_id: str) -> str:
        return self.request("GET", f"/api/v3/tasks/{task_id}/logtail") or ""

    def cancel(self, job_id: str, reason: str = "cancelled from Articula") -> None:
        self.request("POST", f"/api/v3/jobs/{job_id}/setstatus", {"status": "cancel-requested", "reason": reason})

    def workers(self) -> list:
        return self.request("GET", "/api/v3/worker-mgt/workers").get("workers", [])


def _error_text(exc) -> str:
    """The Manager's error message of an HTTP error (its JSON ``message``), else the reason phrase."""
    try:
        return json.loads(exc.read()).get("message") or exc.reason
    except (ValueError, OSError, AttributeError):
        return str(exc.reason)
