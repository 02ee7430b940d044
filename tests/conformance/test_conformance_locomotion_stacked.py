"""Conformance of the envs on Brax's models under the stack of every combinator, one env
per kind of base: the planar hopper (for walker and cheetah) and the joystick (a free
base, the ant, under the most wrappers; the humanoids' free base differs only in size).
Each case costs minutes of CPU compile, hence so few, and a module of their own; every
builder passes the bare conformance in test_conformance_locomotion.py."""

from __future__ import annotations

import pytest
from test_conformance import LOCOMOTION
from test_conformance import check_conformance
from test_conformance import check_new_numbers_do_not_retrace

STACKED = ("hopper", "ant_joystick")
assert set(STACKED) <= set(LOCOMOTION)


@pytest.mark.parametrize("env", STACKED)
def test_conformance(env):
    check_conformance(env, "all")


@pytest.mark.parametrize("env", STACKED)
def test_new_numbers_do_not_retrace(env):
    check_new_numbers_do_not_retrace(env, "all")
