"""Shared by the depth-tracking Blender tests: the solver replaced by a stub that records the options it
is given and stops the run (what the operator or the command passes on, without tracking)."""
import pytest


@pytest.fixture
def solver_options(pkg, monkeypatch):
    """The list the stubbed ``track_recording`` appends its options to; the run ends cancelled."""
    solve = pkg("addon.track_depth.solve")
    seen = []

    def stop(recording, model, options, progress=None):
        seen.append(options)
        raise pkg("solver.errors").Cancelled("stub")

    monkeypatch.setattr(solve, "track_recording", stop)
    return seen
