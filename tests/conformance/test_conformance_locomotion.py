"""Conformance (tests/conformance/test_conformance.py) of the envs on Brax's models, bare, with the
same checks, in a module (and so a process under xdist) of its own; the stacked cases
are in test_conformance_locomotion_stacked.py, so that xdist runs the two side by side.

One env per builder, each compile here costing 40-100 s of the suite's CPU: walker and
cheetah are the hopper's `_planar` builder on other models; humanoid_walk and
humanoid_run are the ant's `_free_runner` on the humanoid (humanoid_run's uncapped
forward reward is checked in tests/envs/test_locomotion.py), and humanoid_standup the
same `gym_task` and free-base observation with no termination (its lying start and
height reward are checked there too); humanoid_amp_walk is humanoid_amp_joystick's
builder without the command. tests/envs/test_locomotion.py traces every one of them
(sizes) and runs the humanoids' transitions; GPU benchmarks train each."""

from __future__ import annotations

import pytest
from test_conformance import LOCOMOTION
from test_conformance import check_conformance
from test_conformance import check_new_numbers_do_not_retrace

SAME_BUILDER_AS = {
    "walker": "hopper",
    "cheetah": "hopper",
    "humanoid_walk": "ant",
    "humanoid_run": "ant",
    "humanoid_standup": "ant",
    "humanoid_amp_walk": "humanoid_amp_joystick",
}
BARE = [env for env in LOCOMOTION if env not in SAME_BUILDER_AS]
assert set(SAME_BUILDER_AS.values()) <= set(BARE)


@pytest.mark.parametrize("env", BARE)
def test_conformance(env):
    check_conformance(env, "bare")


@pytest.mark.parametrize("env", BARE)
def test_new_numbers_do_not_retrace(env):
    check_new_numbers_do_not_retrace(env, "bare")
