"""Conformance (tests/test_conformance.py) of the envs on Brax's models: each bare and
under the stack of every combinator, with the same checks, in a module (and so a
process under xdist) of its own."""

from __future__ import annotations

import pytest

from test_conformance import LOCOMOTION, check_conformance, check_new_numbers_do_not_retrace, check_time_limit

CASES = [(env, comb) for env in LOCOMOTION for comb in ("bare", "all")]


@pytest.mark.parametrize("env,comb", CASES)
def test_conformance(env, comb):
    check_conformance(env, comb)


@pytest.mark.parametrize("env,comb", CASES)
def test_new_numbers_do_not_retrace(env, comb):
    check_new_numbers_do_not_retrace(env, comb)


@pytest.mark.parametrize("env", LOCOMOTION)
def test_time_limit_truncates_and_never_terminates(env):
    check_time_limit(env)
