"""Conformance (tests/test_conformance.py) of the envs on Brax's models, with the same
checks, in a module (and so a process under xdist) of its own: every env bare, and under
the stack of every combinator one env per kind of model and builder (the planar hopper
for walker and cheetah, the humanoid walk for run and standup, the ant, the joystick),
because each stacked case costs minutes of CPU compile."""

from __future__ import annotations

import pytest

from test_conformance import LOCOMOTION, check_conformance, check_new_numbers_do_not_retrace, check_time_limit

STACKED = ("hopper", "ant", "humanoid_walk", "ant_joystick")
assert set(STACKED) <= set(LOCOMOTION)
CASES = [(env, "bare") for env in LOCOMOTION] + [(env, "all") for env in STACKED]


@pytest.mark.parametrize("env,comb", CASES)
def test_conformance(env, comb):
    check_conformance(env, comb)


@pytest.mark.parametrize("env,comb", CASES)
def test_new_numbers_do_not_retrace(env, comb):
    check_new_numbers_do_not_retrace(env, comb)


@pytest.mark.parametrize("env", LOCOMOTION)
def test_time_limit_truncates_and_never_terminates(env):
    check_time_limit(env)
