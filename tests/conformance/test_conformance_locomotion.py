"""Conformance (tests/conformance/test_conformance.py) of the envs on Brax's models, bare, with the
same checks, in a module (and so a process under xdist) of its own; the stacked cases
are in test_conformance_locomotion_stacked.py, so that xdist runs the two side by side.

One env per builder: humanoid_run is humanoid_walk's model, observation, termination and
reset with an uncapped forward reward (tests/envs/test_locomotion.py checks that reward),
and humanoid_amp_walk is humanoid_amp_joystick's builder without the command; each
compile here costs 20-40 s of the suite's CPU."""

from __future__ import annotations

import pytest
from test_conformance import LOCOMOTION
from test_conformance import check_conformance
from test_conformance import check_new_numbers_do_not_retrace

SAME_BUILDER_AS = {"humanoid_run": "humanoid_walk", "humanoid_amp_walk": "humanoid_amp_joystick"}
BARE = [env for env in LOCOMOTION if env not in SAME_BUILDER_AS]
assert set(SAME_BUILDER_AS.values()) <= set(BARE)


@pytest.mark.parametrize("env", BARE)
def test_conformance(env):
    check_conformance(env, "bare")


@pytest.mark.parametrize("env", BARE)
def test_new_numbers_do_not_retrace(env):
    check_new_numbers_do_not_retrace(env, "bare")
