"""LearnOptions: the defaults learn_rig had as keyword arguments before the options object, the bounds
validate() enforces, and learn_rig's keyword settings as a thin way to build the options."""
import math
from dataclasses import FrozenInstanceError, replace

import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.learn.options import LearnOptions, property_range
from articula.solver.learn.pipeline import learn_rig

from articula.sample_scenes.tube_scans import hybrid_truth

# learn_rig's keyword defaults and module constants (GN_GAIN_TOL, OTHER_SCAN_*) before the options object
# (solver/learn.py at b8f0acd); parts, key_scans and workers then used None for "automatic", now 0.
OLD_DEFAULTS = dict(parts=0, alpha=100.0, symmetry=True, max_iterations=4, seed=0, initial_skeleton=None,
                    lam=1e10, gn_iterations=3, bcd_sweeps=3, tol=1e-4, k_max=20, joint_warmup_rounds=1,
                    bcd_steps=(0.2, 0.1, 0.05, 0.02), rest_scan=None, warm_start=(0.01, 0.1), joint_prior=0.01,
                    key_scans=40, workers=0, gn_gain_tol=1e-4, other_scan_iterations=3, other_scan_tol=1e-6)


# defaults changed since: the convergence test relative to the largest round decrease (tol) that stops
# before the raised cap (issue 19), and k_max
CHANGED = dict(max_iterations=8, tol=0.25, k_max=32)


def test_defaults_are_the_former_keyword_defaults():
    opts = LearnOptions()
    assert {name: getattr(opts, name) for name in OLD_DEFAULTS} == {**OLD_DEFAULTS, **CHANGED}
    opts.validate()


def test_none_means_automatic_and_sequences_become_tuples():
    opts = LearnOptions(parts=None, key_scans=None, workers=None, bcd_steps=[0.2], warm_start=[])
    assert (opts.parts, opts.key_scans, opts.workers) == (0, 0, 0)
    assert opts.bcd_steps == (0.2,) and opts.warm_start == ()
    with pytest.raises(FrozenInstanceError):
        opts.alpha = 1.0


@pytest.mark.parametrize("change, message", [
    (dict(alpha=-1.0), "alpha: -1.0 given; it must be at least 0.0"),
    (dict(alpha=math.nan), "alpha: nan given; expected a finite number"),
    (dict(parts=65), "parts: 65 given; it must be from 0 to 64"),
    (dict(max_iterations=2.5), "max_iterations: 2.5 given; expected an integer"),
    (dict(seed=-3), "seed: -3 given"),
    (dict(k_max=1), "k_max: 1 given"),
    (dict(rest_scan=-1), "rest_scan: -1 given"),
    (dict(key_scans=2), "key_scans: 2 given; learning a rig needs at least 3 scans"),
    (dict(key_scans=-1), "key_scans: -1 given"),
    (dict(joint_prior="0.1"), "joint_prior: '0.1' given; expected a finite number"),
    (dict(bcd_steps=()), "bcd_steps: none given"),
    (dict(warm_start=(0.01, 0.0)), "warm_start: 0.0 given; every value must be a positive number"),
])
def test_absurd_values_are_refused_by_name(change, message):
    with pytest.raises(ArticulaInputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        replace(LearnOptions(), **change).validate()


def test_numpy_numbers_and_limits_are_accepted():
    LearnOptions(parts=np.int64(8), alpha=np.float32(1.0), rest_scan=np.int64(0), key_scans=3, k_max=2).validate()
    LearnOptions(parts=64, max_iterations=1000, key_scans=100000, alpha=0.0, tol=0.0).validate()


def test_property_range_is_the_field_default_and_soft_bounds():
    """Soft limits only: Blender clamps to hard limits silently (parts=10000 became 64); the operator's
    out-of-range values must reach LearnOptions.validate and be refused with its message."""
    assert property_range("alpha") == dict(default=100.0, soft_min=0.0, soft_max=1000.0)
    assert property_range("parts") == dict(default=0, soft_min=0, soft_max=64)
    assert property_range("symmetry") == dict(default=True)


def test_keyword_settings_build_the_options():
    """learn_rig(scans, faces, **settings) is learn_rig(scans, faces, LearnOptions(**settings)), and
    keywords replace fields of a given options object."""
    model, _, scans = hybrid_truth(4, seed=2)
    kw = dict(parts=8, max_iterations=1, bcd_sweeps=1, gn_iterations=1, warm_start=(), seed=3, workers=1)
    a = learn_rig(scans, model.faces, **kw)
    b = learn_rig(scans, model.faces, LearnOptions(**kw))
    c = learn_rig(scans, model.faces, LearnOptions(**{**kw, "seed": 0, "parts": 5}), seed=3, parts=8)
    for other in (b, c):
        assert other.report["objective_log"] == a.report["objective_log"]
        assert np.array_equal(other.model.rest_vertices, a.model.rest_vertices)
    with pytest.raises(TypeError):
        learn_rig(scans, model.faces, no_such_setting=1)
    with pytest.raises(ArticulaInputError, match="alpha"):
        learn_rig(scans, model.faces, alpha=-1.0)
