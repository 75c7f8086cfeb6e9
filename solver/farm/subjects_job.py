"""Many subjects on a Flamenco Manager (docs/farm.md): one task per subject folder under a shared root,
running ``learn-rig`` (a model bundle per subject) or ``import-scans`` (a .blend per subject), as the job
of the ``articula-subjects`` job type (``addon/farm/job_types/articula_subjects.js``), followed by
:class:`.follow.FarmRun`."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

from ..errors import ArticulaInputError

JOB_TYPE = "articula-subjects"
COMMANDS = ("learn-rig", "import-scans")


@dataclass
class SubjectsJob:
    """``command``: one of :data:`COMMANDS`; ``root``: shared folder of subject folders; ``subjects``:
    their names; ``out_dir``: where ``<subject>.npz``/``.json``/``.blend`` land; ``blend``: learn-rig
    also saves a .blend; ``options``: further flags (no paths)."""
    command: str
    root: str
    subjects: list
    out_dir: str
    blend: bool = False
    options: list = field(default_factory=list)
    name: str = ""

    job_type = JOB_TYPE
    unit = "subject"
    has_finish = False

    def __post_init__(self):
        if self.command not in COMMANDS:
            raise ArticulaInputError(f"command {self.command!r}: expected one of {', '.join(COMMANDS)}")
        bad = [s for s in self.subjects if not s or "/" in s or "\\" in s or s in (".", "..")]
        if bad or not self.subjects:
            raise ArticulaInputError(f"subjects: expected folder names under {self.root}, got {bad or 'none'}")

    @property
    def count(self) -> int:
        return len(self.subjects)

    def outputs_pending(self, done) -> list:
        """The result files of the subjects not in ``done`` (indices)."""
        ext = ".npz" if self.command == "learn-rig" else ".blend"
        return [os.path.join(self.out_dir, s + ext) for k, s in enumerate(self.subjects) if k not in done]

    def unit_of(self, task_name: str):
        """Subject number of a task named ``<command> <subject>``."""
        name = task_name.split(" ", 1)[-1]
        return self.subjects.index(name) if name in self.subjects else None

    def prepare(self) -> None:
        """Make the folder the tasks write into (on the shared storage)."""
        try:
            os.makedirs(self.out_dir, exist_ok=True)
        except OSError as exc:
            raise ArticulaInputError(f"{self.out_dir}: cannot make the folder ({exc.strerror or exc})") from None

    def body(self, run) -> dict:
        settings = {"command": self.command, "root": self.root, "subjects": "/".join(self.subjects[k] for k in run),
                    "out_dir": self.out_dir, "blend": bool(self.blend), "options": " ".join(self.options)}
        name = self.name or f"Articula {self.command} {os.path.basename(os.path.normpath(self.root))}"
        return {"name": name, "type": JOB_TYPE, "settings": settings, "metadata": {}}

    def repair(self, done: set) -> str:
        """Nothing to repair between subjects (they are independent)."""
        return ""

    def is_prep(self, task_name: str) -> bool:
        """Subjects have no first task."""
        return False

    def prep_done(self) -> None:
        """Subjects have no first task."""
