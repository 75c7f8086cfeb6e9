"""Following a job on a Flamenco Manager to its end (docs/farm.md).

A job is made of units (the chunks of a recording, the subjects of a batch), one task each, and
optionally a finishing task (the merge).  :class:`FarmRun` submits it and follows it one poll at a time
(:meth:`FarmRun.poll`, for the panel's timer) or to the end (:meth:`FarmRun.wait`, for the batch
commands).  When the job fails -- with fewer than three Workers one failed task fails the whole job --
only the units that did not complete are submitted again, a bounded number of times.  When only the
finishing task failed, the work's ``repair`` decides what to run again (chunks that started on another
solution); a finishing task that nothing can repair is never submitted again.  The work object
(:class:`.track_job.TrackJob`, :class:`.subjects_job.SubjectsJob`) gives ``job_type``, ``unit``,
``count``, ``has_finish``, ``outputs_pending(done)`` (the outputs of the units not in ``done`` and of the
finishing task), ``prepare()`` (makes its folders), ``unit_of(task_name)``, ``body(run)`` and
``repair(done)`` (after a failed finish with every unit done: units to run again, removed from ``done``,
and a line saying why; '' when none; raises :class:`ArticulaInputError` saying why it cannot),
``is_prep(task_name)`` and ``prep_done()`` (a first task the units wait for, e.g. adapting the template)."""
from __future__ import annotations

import os
import time
from collections import Counter
from dataclasses import dataclass

from ..errors import ArticulaInputError, Cancelled
from ..formats.bundle import temporary_path
from .flamenco import FarmError, Manager


@dataclass
class Status:
    """One poll's view: the job's Manager status; per unit ``"queued"|"active"|"completed"|"failed"|...``
    (units done in an earlier submission are "completed"); the finishing task's status ("none" when
    the job has none); the submission number (1 = first) and a line for the user."""
    job_id: str
    job_status: str
    unit_status: list
    finish_status: str
    attempt: int
    text: str

    @property
    def fraction(self) -> float:
        """Share of the tasks completed, 0..1."""
        finish = self.finish_status != "none"
        done = sum(s == "completed" for s in self.unit_status) + (self.finish_status == "completed")
        return done / (len(self.unit_status) + finish)


class FarmRun:
    """Submit ``work`` to ``manager`` and follow it; ``retries``: how many times a failed job's
    unfinished units are submitted again before giving up (repairs of a failed finish, bounded by the
    work, do not count)."""

    def __init__(self, manager: Manager, work, retries: int = 2):
        if int(retries) != retries or not 0 <= retries <= 20:
            raise ArticulaInputError(f"retries: expected a whole number in 0..20, got {retries}")
        self.manager, self.work, self.retries = manager, work, int(retries)
        self.done = set()                      # units completed in any submission
        self.attempt, self.job_id, self.jobs, self.last = 0, "", [], None
        self.repairs = 0                       # submissions that repaired a failed finish (not retries)
        self.prep_status = ""                  # the status of a task the units wait for ("" when none)

    def start(self) -> str:
        """Check the Manager knows the job type, then submit the units not yet done; returns the job id."""
        self.manager.require_job_type(self.work.job_type)
        run = [k for k in range(self.work.count) if k not in self.done]
        self.work.prepare()
        record = self.manager.submit(self.work.body(run))
        self.attempt += 1
        self.job_id = record["id"]
        self.jobs.append(self.job_id)
        return self.job_id

    def poll(self) -> Status:
        """Read the job and its tasks once.  A failed job is submitted again for its unfinished units
        (while retries remain); raises :class:`FarmError` when it cannot finish or was cancelled."""
        record, tasks = self.manager.job(self.job_id), self.manager.tasks(self.job_id)
        unit_status, finish_status = self._task_status(tasks)
        status = record["status"]
        self.last = Status(self.job_id, status, unit_status, finish_status, self.attempt,
                           self._text(status, unit_status, finish_status))
        if status == "canceled":
            raise FarmError(f"job {self.job_id} was cancelled on the Manager; {self._outputs_state()}")
        if status == "failed":
            self._retry_or_raise(tasks)
        return self.last

    def _task_status(self, tasks):
        unit_status = ["completed" if k in self.done else "not submitted" for k in range(self.work.count)]
        finish_status = "queued" if self.work.has_finish else "none"
        for t in tasks:
            if self.work.is_prep(t["name"]):
                self.prep_status = t["status"]
                if t["status"] == "completed":
                    self.work.prep_done()
                continue
            k = self.work.unit_of(t["name"])
            if k is None:
                finish_status = t["status"]
                continue
            unit_status[k] = t["status"]
            if t["status"] == "completed":
                self.done.add(k)
        return unit_status, finish_status

    def _retry_or_raise(self, tasks) -> None:
        failed = [t for t in tasks if t["status"] == "failed"]
        names = ", ".join(t["name"] for t in failed) or "a task"
        if len(self.done) == self.work.count:          # only the finishing task failed: repair or stop
            try:
                repaired = self.work.repair(self.done)
            except ArticulaInputError as exc:
                self._give_up(failed, f"{names} failed (job {self.job_id}): {exc}")
            if not repaired:
                self._give_up(failed, f"{names} failed with every {self.work.unit} done (job {self.job_id}); not "
                                      f"submitted again: it would read the same inputs")
            self.repairs += 1
            self.start()
            self.last.text += f"; {repaired}: submitted again as job {self.job_id}"
            return
        if self.attempt - self.repairs > self.retries:
            self._give_up(failed, f"{names} failed in {self.attempt} submissions (last job {self.job_id})")
        self.start()
        self.last.text += f"; {names} failed: submitted again as job {self.job_id}"

    def _give_up(self, failed, text: str) -> None:
        """Raise :class:`FarmError` with ``text``, the outputs' state and the end of the first failed task's
        log."""
        tail = self._log_tail(failed[0]) if failed else ""
        raise FarmError(f"{text}; {self._outputs_state()}" + (f"; the end of its log:\n{tail}" if tail else ""))

    def _log_tail(self, task) -> str:
        try:
            return "\n".join(str(self.manager.log_tail(task["id"])).strip().splitlines()[-8:])
        except FarmError:
            return ""

    def _outputs_state(self) -> str:
        """Remove what a stopped task may have left half-written beside the outputs it did not finish;
        say how far the job got and what those outputs are."""
        pending = self.work.outputs_pending(self.done)
        for out in pending:
            remove_partial(out)
        state = "; ".join(f"{out} {'is as before' if os.path.exists(out) else 'was not written'}" for out in pending)
        done = f"{len(self.done)} of {self.work.count} {self.work.unit}s done"
        return f"{done}; {state}" if state else done

    def cancel(self) -> str:
        """Ask the Manager to cancel the current job (its running tasks are stopped); returns a line
        saying what the outputs are."""
        if self.job_id:
            self.manager.cancel(self.job_id)
        return self._outputs_state()

    def wait(self, poll_seconds: float = 2.0, report=print, cancelled=lambda: False) -> Status:
        """Follow the job to its end, calling ``report(text)`` whenever the status line changes;
        ``cancelled()`` True cancels the job and raises :class:`Cancelled`."""
        if not self.job_id:
            self.start()
        shown = ""
        while True:
            if cancelled():
                raise Cancelled(f"(job {self.job_id}: {self.cancel()})")
            status = self.poll()
            if status.text != shown:
                report(status.text)
                shown = status.text
            if status.job_status == "completed":
                return status
            time.sleep(poll_seconds)

    def _text(self, job_status, unit_status, finish_status) -> str:
        parts = ", ".join(f"{n} {s}" for s, n in sorted(Counter(unit_status).items()))
        again = f" (submission {self.attempt})" if self.attempt > 1 else ""
        prep = f"adapting {self.prep_status}; " if self.prep_status and self.prep_status != "completed" else ""
        finish = f"; finish {finish_status}" if finish_status != "none" else ""
        return f"job {self.job_id[:8]} {job_status}{again}: {prep}{self.work.unit}s {parts}{finish}"


def remove_partial(out: str) -> None:
    """Remove the temporary file a stopped task may leave beside ``out`` (bundles are written to
    :func:`solver.formats.bundle.temporary_path` and renamed; Blender saves to ``out@`` and renames)."""
    for tmp in (temporary_path(out), out + "@"):
        if os.path.isfile(tmp):
            try:
                os.remove(tmp)
            except OSError:
                pass
