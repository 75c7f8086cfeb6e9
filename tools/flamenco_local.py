"""A Flamenco farm on this machine for tests and benchmarks: builds the Manager and Worker once from the
Flamenco source tarball (cached under ``$ARTICULA_HOME/flamenco/<tarball>``), then runs a Manager and
Workers on 127.0.0.1 with SQLite in a temporary folder (:class:`LocalFarm`).  Every process runs in its
own process group, is bounded in time and stopped by its PID.  Flamenco (GPL-3) is a separate program:
built from its source here, talked to over HTTP, never linked or shipped.

    python tools/flamenco_local.py build          # build (or find) the binaries, print where
    python tools/flamenco_local.py check          # say whether the farm tests can run here
"""
from __future__ import annotations

import glob
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tarfile
import tempfile
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
GO_MIN = (1, 26)
BUILD_SECONDS = 900
START_SECONDS = 60


def home() -> str:
    return os.environ.get("ARTICULA_HOME", os.path.expanduser("~/.cache/articula"))


def tarball() -> str:
    """The Flamenco source tarball: ``$ARTICULA_FLAMENCO_TARBALL``, else the one in the shared vendor
    folder beside the checkout."""
    given = os.environ.get("ARTICULA_FLAMENCO_TARBALL")
    if given:
        return given
    found = sorted(glob.glob(os.path.join(os.path.dirname(ROOT), "shared", "vendor", "flamenco-*.tar.gz")))
    return found[-1] if found else ""


def go_version():
    """(major, minor) of the ``go`` on PATH (or /usr/local/go/bin/go), else None."""
    for exe in (shutil.which("go"), "/usr/local/go/bin/go"):
        if exe and os.path.exists(exe):
            try:
                out = subprocess.run([exe, "version"], capture_output=True, text=True, timeout=30).stdout
            except (OSError, subprocess.TimeoutExpired):
                continue
            m = re.search(r"go(\d+)\.(\d+)", out)
            if m:
                return (int(m.group(1)), int(m.group(2))), exe
    return None, None


def availability() -> str:
    """"" when the farm can be built here, else why not."""
    version, _ = go_version()
    if version is None:
        return "no Go toolchain (go) found"
    if version < GO_MIN:
        return f"Go {version[0]}.{version[1]} found, Flamenco needs Go >= {GO_MIN[0]}.{GO_MIN[1]}"
    if not tarball() or not os.path.isfile(tarball()):
        return "the Flamenco source tarball (shared/vendor/flamenco-*.tar.gz) was not found"
    return ""


def build() -> str:
    """Folder holding ``flamenco-manager`` and ``flamenco-worker``, built on first use."""
    reason = availability()
    if reason:
        raise RuntimeError(f"cannot build Flamenco: {reason}")
    stem = os.path.basename(tarball())[:-len(".tar.gz")]
    dest = os.path.join(home(), "flamenco", stem)
    bins = os.path.join(dest, "bin")
    if all(os.path.isfile(os.path.join(bins, n)) for n in ("flamenco-manager", "flamenco-worker")):
        return bins
    _, go = go_version()
    os.makedirs(dest, exist_ok=True)
    work = tempfile.mkdtemp(prefix="build-", dir=dest)
    try:
        with tarfile.open(tarball()) as tar:
            tar.extractall(work, filter="data") if sys.version_info >= (3, 12) else tar.extractall(work)
        src = next(os.path.dirname(p) for p in glob.glob(os.path.join(work, "*", "go.mod")))
        out = os.path.join(work, "bin")
        env = dict(os.environ, CGO_ENABLED="0")
        for name in ("flamenco-manager", "flamenco-worker"):
            print(f"flamenco_local: building {name} (go build, first time only)", file=sys.stderr, flush=True)
            subprocess.run([go, "build", "-o", os.path.join(out, name), f"./cmd/{name}"], cwd=src, env=env,
                           check=True, timeout=BUILD_SECONDS)
        if os.path.isdir(bins):
            shutil.rmtree(bins)
        os.replace(out, bins)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return bins


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _write_config(path: str, config: dict) -> None:
    """Write a Flamenco configuration file: JSON, which YAML parsers read as YAML (flow style)."""
    with open(path, "w") as fh:
        json.dump(config, fh, indent=1)



class LocalFarm:
    """A Manager and ``workers`` Workers on 127.0.0.1 under ``folder``, the job types of ``job_types``
    (a folder of .js files) installed, ``{articula}`` = ``articula``.  ``two_way``: optional
    ``{name: {platform: path}}`` two-way variables.  Use as a context manager."""

    def __init__(self, folder: str, job_types: str, articula: str, workers: int = 2, two_way=None,
                 worker_timeout: str = "20s", env=None):
        self.folder, self.job_types, self.articula = folder, job_types, articula
        self.num_workers, self.two_way, self.worker_timeout = workers, two_way or {}, worker_timeout
        self.env = dict(os.environ, **(env or {}))
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.manager, self.workers = None, []

    def __enter__(self):
        bins = build()
        try:
            self._start_manager(bins)
            for k in range(self.num_workers):
                self.workers.append(self._start_worker(bins, k))
            self._wait_workers()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc):
        self.stop()

    def _config(self) -> dict:
        variables = {"articula": {"values": [{"platform": "all", "value": self.articula}]}}
        for name, values in self.two_way.items():
            variables[name] = {"is_twoway": True,
                               "values": [{"platform": p, "value": v} for p, v in values.items()]}
        return {"_meta": {"version": 3}, "manager_name": "articula-test", "database": "flamenco-manager.sqlite",
                "listen": f"127.0.0.1:{self.port}", "autodiscoverable": False,
                "local_manager_storage_path": "./storage", "shared_storage_path": os.path.join(self.folder, "shared"),
                "shaman": {"enabled": False}, "task_timeout": "10m", "worker_timeout": self.worker_timeout,
                "blocklist_threshold": 3, "task_fail_after_softfail_count": 3, "variables": variables}

    def _start_manager(self, bins) -> None:
        mdir = os.path.join(self.folder, "manager")
        os.makedirs(os.path.join(mdir, "scripts"), exist_ok=True)
        os.makedirs(os.path.join(self.folder, "shared"), exist_ok=True)
        exe = os.path.join(mdir, "flamenco-manager")
        shutil.copy2(os.path.join(bins, "flamenco-manager"), exe)   # scripts/ are found beside the executable
        for js in glob.glob(os.path.join(self.job_types, "*.js")):
            shutil.copy2(js, os.path.join(mdir, "scripts"))
        _write_config(os.path.join(mdir, "flamenco-manager.yaml"), self._config())
        self.manager = self._spawn([exe], mdir, "manager.log")
        deadline = time.monotonic() + START_SECONDS
        while time.monotonic() < deadline:
            if self.manager.poll() is not None:
                raise RuntimeError(f"the Manager exited ({self.manager.returncode}); see {mdir}/manager.log")
            try:
                urllib.request.urlopen(self.url + "/api/v3/version", timeout=2).read()
                return
            except OSError:
                time.sleep(0.3)
        raise RuntimeError(f"the Manager did not answer within {START_SECONDS} s; see {mdir}/manager.log")

    def _start_worker(self, bins, k):
        wdir = os.path.join(self.folder, f"worker{k}")
        os.makedirs(wdir, exist_ok=True)
        _write_config(os.path.join(wdir, "flamenco-worker.yaml"),
                      {"manager_url": self.url, "worker_name": f"articula-test-{k}",
                       "task_types": ["misc", "blender", "ffmpeg", "file-management"], "restart_exit_code": 47})
        return self._spawn([os.path.join(bins, "flamenco-worker")], wdir, "worker.log", FLAMENCO_HOME=wdir)

    def _spawn(self, cmd, cwd, log, **env):
        out = open(os.path.join(cwd, log), "ab")
        try:
            return subprocess.Popen(cmd, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                                    env=dict(self.env, **env))
        finally:
            out.close()

    def _wait_workers(self) -> None:
        deadline = time.monotonic() + START_SECONDS
        while time.monotonic() < deadline:
            if self.awake_workers() >= self.num_workers:
                return
            time.sleep(0.5)
        raise RuntimeError(f"{self.num_workers} Workers did not sign on within {START_SECONDS} s; see "
                           f"{self.folder}/worker*/worker.log")

    def awake_workers(self) -> int:
        with urllib.request.urlopen(self.url + "/api/v3/worker-mgt/workers", timeout=5) as r:
            return sum(w.get("status") == "awake" for w in json.loads(r.read()).get("workers", []))

    def kill_worker(self, k: int) -> None:
        """Kill Worker ``k`` and everything it started (SIGKILL to its process group): a machine dying."""
        _kill(self.workers[k], signal.SIGKILL)

    def stop(self) -> None:
        """Stop the Workers, then the Manager: SIGTERM to each process group, SIGKILL after 10 s."""
        for proc in self.workers + [self.manager]:
            if proc is not None:
                _kill(proc, signal.SIGTERM)
        for proc in self.workers + [self.manager]:
            if proc is not None:
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    _kill(proc, signal.SIGKILL)
                    proc.wait(timeout=10)


def _kill(proc, sig) -> None:
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "check"
    if what == "build":
        print(build())
    else:
        reason = availability()
        print("farm tests can run: Go and the Flamenco tarball found" if not reason else f"farm tests cannot run: {reason}")
        sys.exit(0 if not reason else 1)
