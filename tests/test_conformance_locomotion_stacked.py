"""Conformance of the envs on Brax's models under the stack of every combinator, one env
per kind of model and builder: the planar hopper (for walker and cheetah), the humanoid
walk (for run and standup) and the joystick (the ant under the most wrappers). Each case
costs minutes of CPU compile, hence so few, and a module of their own."""

from __future__ import annotations

import pytest

from test_conformance import LOCOMOTION, check_conformance, check_new_numbers_do_not_retrace

STACKED = ("hopper", "humanoid_walk", "ant_joystick")
assert set(STACKED) <= set(LOCOMOTION)


@pytest.mark.parametrize("env", STACKED)
def test_conformance(env):
    check_conformance(env, "all")


@pytest.mark.parametrize("env", STACKED)
def test_new_numbers_do_not_retrace(env):
    check_new_numbers_do_not_retrace(env, "all")
