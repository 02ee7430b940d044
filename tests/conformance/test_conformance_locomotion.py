"""Conformance (tests/conformance/test_conformance.py) of the envs on Brax's models, bare, with the
same checks, in a module (and so a process under xdist) of its own; the stacked cases
are in test_conformance_locomotion_stacked.py, so that xdist runs the two side by side."""

from __future__ import annotations

import pytest
from test_conformance import LOCOMOTION
from test_conformance import check_conformance
from test_conformance import check_new_numbers_do_not_retrace


@pytest.mark.parametrize("env", LOCOMOTION)
def test_conformance(env):
    check_conformance(env, "bare")


@pytest.mark.parametrize("env", LOCOMOTION)
def test_new_numbers_do_not_retrace(env):
    check_new_numbers_do_not_retrace(env, "bare")
