"""Warnings raised from the solver's code fail the tests (``tests/conftest.py``), elsewhere they do not."""
import warnings

import numpy as np
import pytest


def _add_infinities(module_name: str):
    """``inf + -inf`` (numpy's "invalid value encountered in add") run as code of ``module_name``."""
    code = compile("np.array([np.inf]) + np.array([-np.inf])", f"<{module_name}>", "eval")
    return eval(code, {"np": np, "__name__": module_name})


@pytest.mark.parametrize("module", ["articula.solver.tracking.pose_prior",
                                    "bl_ext.articula_test.articula.solver.tracking.pose_prior"])
def test_a_warning_in_the_solver_is_an_error(module):
    with pytest.raises(RuntimeWarning, match="invalid value"):
        _add_infinities(module)


@pytest.mark.parametrize("module", ["articula.sample_scenes.walk", "some_other_package.solver"])
def test_a_warning_elsewhere_stays_a_warning(module):
    with warnings.catch_warnings(record=True) as caught:
        assert np.isnan(_add_infinities(module)[0])
    assert any("invalid value" in str(w.message) for w in caught)
