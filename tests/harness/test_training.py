"""`training.run` drives an algorithm value (`mjzoo.learning.Algorithm`): what a value
lacks is named in one error before anything runs; the per-env fields it names are the
ones sharded; evaluation runs the task's own episode length unless told otherwise; the
schedules of evaluations, checkpoints and metrics lines, driven by a fake clock through
`run`'s `clock` and `hooks`."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
import types
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import learning
from mjzoo.harness import devices
from mjzoo.harness import metrics
from mjzoo.harness import rendering
from mjzoo.harness import training
from mjzoo.harness.cli import runs
from tests.harness.test_rendering import egl_installed

XML = """
<mujoco model="block">
  <worldbody><body><joint name="x" type="slide"/><geom type="box" size="0.1 0.1 0.1"/></body></worldbody>
  <actuator><motor joint="x"/></actuator>
</mujoco>
"""
TASK = mjzoo.task(XML, time_limit=7)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Count:
    updates: jax.Array
    per_env: jax.Array  # [num_envs]


@dataclasses.dataclass(frozen=True)
class CountConfig:
    steps_per_update: int = 10


def counter(num_updates: int = 2, **overrides) -> learning.Algorithm:
    """An algorithm value whose state counts its updates; its evaluation returns num_steps."""
    algorithm = learning.Algorithm(
        name="counter",
        config=CountConfig(),
        hyperparams=None,
        init=lambda task, hyperparams, key: Count(jnp.zeros((), jnp.int32), jnp.zeros(4)),
        update=lambda task, s: (Count(s.updates + 1, s.per_env + 1.0), {}),
        evaluate=lambda task, s, key, n, steps: learning.Evaluation(
            jnp.full(n, steps, jnp.float32), jnp.full(n, steps), None
        ),
        policy=lambda task, deterministic=True: lambda params, obs, key: obs,
        policy_params=lambda s: s,
        steps_per_update=10,
        num_updates=num_updates,
        per_env_fields=("per_env",),
    )
    return algorithm._replace(**overrides)


SETTINGS = training.Settings(updates_per_chunk=1, video=False, progress=False)


def test_evaluation_runs_the_task_s_own_episode_length():
    state, last = training.run(counter(), TASK, SETTINGS)
    assert last["eval/return"] == 7.0 and int(state.updates) == 2
    _, last = training.run(counter(), TASK, dataclasses.replace(SETTINGS, eval_steps=3))
    assert last["eval/return"] == 3.0


def test_a_task_without_time_limit_needs_eval_steps():
    with pytest.raises(
        ValueError, match=r"eval_steps=None: the task's own episode length\): the task has no time limit"
    ):
        training.run(counter(), TASK.replace(time_limit=None), SETTINGS)


def test_what_an_algorithm_value_lacks_is_named_at_once():
    lacking = types.SimpleNamespace(**{**counter()._asdict(), "evaluate": None, "per_env_fields": None})
    del lacking.steps_per_update
    with pytest.raises(
        TypeError,
        match=r"counter is not an algorithm value of the mjzoo.learning.Algorithm contract \(e.g. ppo.make\(config\)\); "
        r"it lacks evaluate\(\), per_env_fields \(.*\), steps_per_update \(an int >= 1\)",
    ):
        training.run(lacking, TASK, SETTINGS)
    with pytest.raises(TypeError, match=r"must be a dataclass with the fields \['per_env_typo'\]"):
        training.run(counter(per_env_fields=("per_env_typo",)), TASK, SETTINGS)


def test_per_env_fields_are_sharded_the_rest_replicated():
    """On one device: everything placed on it (the state is committed, see shard_envs)."""
    state = devices.shard_envs(Count(jnp.zeros((), jnp.int32), jnp.zeros(4)), ("per_env",))
    assert state.per_env.committed and state.updates.committed


def test_init_is_jitted_by_the_harness():
    traces = []

    def init(task, hyperparams, key):
        traces.append(isinstance(key, jax.core.Tracer))
        return Count(jnp.zeros((), jnp.int32), jnp.zeros(4))

    training.run(counter(init=init), TASK, SETTINGS)
    assert traces == [True]  # traced (under jit), once


# KSim's validation and logging options. One update function for all of them, so they
# share one compile of its chunk (the harness caches it per update function and length).
def _logging_update(task, s):
    return Count(s.updates + 1, s.per_env + 1.0), {"loss/n": s.updates * 1.0}


def logging(num_updates: int = 2) -> learning.Algorithm:
    return counter(num_updates, update=_logging_update)


class FakeClock:
    """`run`'s clock, driven by its hooks: each chunk of updates takes 10 s, each
    evaluation `eval_s`; nothing else takes time. The evaluation's background compile
    ends at `eval_compile_s` after launch (the evaluation itself then compiles at its
    first call)."""

    def __init__(self, eval_s: float = 0.0, eval_compile_s: float = 0.0) -> None:
        self.now = 0.0

        def advance(seconds: float):
            def hook(*_) -> None:
                self.now += seconds

            return hook

        def join(timeout: float | None = None) -> None:  # a look (timeout 0) takes no time; a wait, until done
            if timeout != 0:
                self.now = max(self.now, eval_compile_s)

        compiling = types.SimpleNamespace(join=join, is_alive=lambda: self.now < eval_compile_s)
        self.hooks = training.Hooks(
            on_chunk=advance(10.0),
            on_evaluation=advance(eval_s),
            compile_evaluation=lambda *args, **kwargs: compiling,
        )

    def __call__(self) -> float:
        return self.now


def lines(tmp_path, chunks: int, clock: FakeClock | None = None, **settings) -> list[dict]:
    """metrics.jsonl of a run of `chunks` one-update chunks (step = 10 x chunk number)."""
    clock = clock or FakeClock()
    settings = dataclasses.replace(SETTINGS, out_dir=tmp_path, checkpoint_every=0, overwrite=True, **settings)
    training.run(logging(chunks), TASK, settings, clock=clock, hooks=clock.hooks)
    return metrics.read_metrics(tmp_path)


def evaluated(records: list[dict]) -> list[int]:
    """The chunk numbers whose metrics line holds an evaluation."""
    return [r["step"] // 10 for r in records if "eval/return" in r]


@pytest.mark.parametrize(
    "settings, chunks",
    [
        ({}, [1, 2, 3, 4, 5, 6, 7]),  # by the 5% budget: evaluating takes no (fake) time, so every chunk
        ({"eval_every": 1}, [1, 2, 3, 4, 5, 6, 7]),  # every chunk
        ({"eval_every": 3}, [3, 6, 7]),  # multiples of 3; the last chunk always evaluates
        ({"eval_every": 0}, [7]),  # only at the end
        ({"eval_every": 0, "eval_every_seconds": 35}, [4, 7]),  # 40 s after launch; 80 s is past the end
        ({"eval_every": 5, "eval_every_seconds": 25}, [3, 5, 7]),  # either trigger: 30 s, chunk 5 (then 20 s < 25)
        ({"eval_every": 2, "eval_first_seconds": 45}, [5, 6, 7]),  # none before 45 s; the first chance; then 2s
        ({"eval_every": 0, "eval_first_seconds": 0}, [1, 7]),  # KSim's "first validation after M seconds"
    ],
)
def test_evaluation_schedule(tmp_path, settings, chunks):
    records = lines(tmp_path, 7, log_every=1, **settings)
    assert [r["step"] for r in records] == [10 * c for c in range(1, 8)]  # every chunk logged (log_every=1)
    assert evaluated(records) == chunks
    assert all(r["perf/eval_s"] == 0.0 for r in records)  # in every line; evaluating takes no fake time
    assert records[0]["perf/first_update_s"] == 10.0 and all("perf/first_update_s" not in r for r in records[1:])


@pytest.mark.parametrize(
    "budget, chunks",
    [
        # Chunks take 10 s and evaluations 2 s. Evaluated when the evaluations so far and one
        # more fit in budget x the time since launch: 0.05: the first (to learn the cost), then
        # at t=82 (2 + 2 <= 0.05 x 82), t=124 would be next but 12 is the last; 0.1: t >= 40,
        # 60, 80, 100, 120; 0.2: every chunk (2 s of every 12 is 17%).
        (0.05, [1, 8, 12]),
        (0.1, [1, 4, 6, 8, 10, 11, 12]),
        (0.2, list(range(1, 13))),
    ],
)
def test_evaluation_by_budget_keeps_its_share_of_the_wall_clock(tmp_path, budget, chunks):
    records = lines(tmp_path, 12, FakeClock(eval_s=2.0), log_every=1, eval_budget=budget, eval_count=0)
    assert evaluated(records) == chunks
    before_last = records[-2]  # the last chunk always evaluates, whatever the budget
    assert sum(r["perf/eval_s"] for r in records[:-1]) <= budget * before_last["perf/elapsed_s"] + 1e-9


def test_the_default_schedule_evaluates_20_times_where_the_budget_alone_gave_4(tmp_path):
    """A 5-minute run of 30 chunks of 10 s whose evaluations take 3.75 s (a GPU run's,
    latency-bound): the 5% budget alone affords 4 and the last, eval_count's marks 20
    evenly spaced (and the budget's first, to learn the cost)."""
    by_budget = evaluated(lines(tmp_path / "budget", 30, FakeClock(eval_s=3.75), eval_count=0))
    assert by_budget == [1, 15, 22, 29, 30]
    counted = evaluated(lines(tmp_path / "count", 30, FakeClock(eval_s=3.75)))
    assert len(counted) == 21 and counted[-1] == 30
    assert max(np.diff(counted)) <= 2  # evenly spaced: every 1.5 chunks


def test_the_default_schedule_cuts_chunks_so_a_short_run_evaluates_20_times(tmp_path):
    """60 updates at updates_per_chunk=10 were 6 chunks, so at most 6 evaluations: by
    default they become 20 chunks of 3, each passing a mark; eval_every keeps the
    chunks as asked."""
    clock = FakeClock(eval_s=5.0)
    settings = dataclasses.replace(SETTINGS, out_dir=tmp_path, updates_per_chunk=10, checkpoint_every=0)
    training.run(logging(60), TASK, settings, clock=clock, hooks=clock.hooks)
    records = metrics.read_metrics(tmp_path)
    assert [r["step"] for r in records] == [30 * c for c in range(1, 21)]  # 3 updates of 10 steps a chunk
    assert sum("eval/return" in r for r in records) == 20
    clock = FakeClock(eval_s=5.0)
    every = dataclasses.replace(settings, eval_every=2, overwrite=True)
    training.run(logging(60), TASK, every, clock=clock, hooks=clock.hooks)
    assert [r["step"] for r in metrics.read_metrics(tmp_path)] == [100 * c for c in range(1, 7)]


@pytest.mark.parametrize(
    "settings, chunks, first_eval_s",
    [
        # By the budget, training goes on meanwhile: chunks 1 and 2 do not evaluate, chunk 3
        # (t=30) does, 2 s; then 2 + 2 <= 0.05 x 82 (chunk 8), 6 <= 0.05 x 124 (the last).
        ({"eval_count": 0}, [3, 8, 12], 2.0),
        # By eval_count's marks (every chunk of 12 passes one): the first waits for the
        # compile (as the last evaluation would), so the curve has its 12 points.
        ({}, list(range(1, 13)), 22.0),
        # Asked for every chunk: the first evaluation waits from t=10 to t=30 (reported as it
        # was), not charged to a budget: charged, it held off every later evaluation.
        ({"eval_every": 1}, list(range(1, 13)), 22.0),
    ],
)
def test_an_evaluation_still_compiling_is_put_off_by_the_budget_and_waited_for_on_request(
    tmp_path, settings, chunks, first_eval_s
):
    """The evaluation compiles in the background until t=30 (a humanoid's on a GPU: ~20 s
    after the first update)."""
    records = lines(tmp_path, 12, FakeClock(eval_s=2.0, eval_compile_s=30.0), log_every=1, **settings)
    assert evaluated(records) == chunks
    assert records[chunks[0] - 1]["perf/eval_s"] == first_eval_s


@pytest.mark.parametrize(
    "settings, chunks",
    [
        ({}, [6, 7]),  # once a minute (chunks take 10 s), and the last chunk
        ({"checkpoint_every": 1}, [1, 2, 3, 4, 5, 6, 7]),
        ({"checkpoint_every": 0}, []),  # never, not even at the end
        ({"checkpoint_every": 3, "checkpoint_every_seconds": None}, [3, 6, 7]),
        ({"checkpoint_every_seconds": 15}, [2, 4, 6, 7]),  # 20 s after launch, then 20 s after each save
        ({"checkpoint_every": 5, "checkpoint_every_seconds": 25}, [3, 5, 7]),  # either trigger; the clock restarts at 5
    ],
)
def test_checkpoint_schedule(tmp_path, monkeypatch, settings, chunks):
    clock, saved = FakeClock(), []
    monkeypatch.setattr(training.checkpoints, "save", lambda directory, step, state: saved.append(step))  # no disk
    run = dataclasses.replace(SETTINGS, out_dir=tmp_path, **settings)
    training.run(logging(7), TASK, run, clock=clock, hooks=clock.hooks)
    assert saved == [10 * c for c in chunks]


def test_hooks_see_every_chunk_evaluation_and_metrics_line():
    seen = []
    hooks = training.Hooks(
        on_chunk=lambda updates, m: seen.append(("chunk", updates, float(m["loss/n"]))),
        on_evaluation=lambda step, value: seen.append(("evaluation", step, value)),
        on_metrics=lambda step, m: seen.append(("metrics", step, m["loss/n"])),
    )
    settings = dataclasses.replace(SETTINGS, eval_every=2, eval_steps=3)
    training.run(logging(3), TASK, settings, hooks=hooks)
    assert seen == [
        ("chunk", 1, 0.0),
        ("metrics", 10, 0.0),
        ("chunk", 2, 1.0),
        ("evaluation", 20, 3.0),
        ("metrics", 20, 1.0),
        ("chunk", 3, 2.0),
        ("evaluation", 30, 3.0),  # the last chunk always evaluates
        ("metrics", 30, 2.0),
    ]


def test_log_every_and_log_train_metrics_choose_what_metrics_jsonl_holds(tmp_path):
    records = lines(tmp_path, 6, eval_every=3, log_every=2)
    assert [r["step"] // 10 for r in records] == [2, 3, 4, 6]  # every 2nd chunk, and each evaluation
    assert evaluated(records) == [3, 6]
    assert [r["loss/n"] for r in records] == [1.0, 2.0, 3.0, 5.0]  # that chunk's own
    assert records[0]["perf/first_update_s"] == 10.0  # carried to the first line written
    records = lines(tmp_path, 6, eval_every=3, log_every=2, log_train_metrics=False)
    assert [r["step"] // 10 for r in records] == [2, 3, 4, 6]
    assert {k.split("/")[0] for r in records for k in r if k != "step"} == {"eval", "perf"}


def test_progress_shows_the_first_update_and_the_training_rate(capsys):
    clock = FakeClock()
    _, last = training.run(
        logging(2), TASK, dataclasses.replace(SETTINGS, progress=True), clock=clock, hooks=clock.hooks
    )
    assert last["perf/steps_per_s"] == 1.0 and last["perf/elapsed_s"] == 20.0  # 10 steps in 10 s of chunk
    assert "first=10.0s" in capsys.readouterr().out


def test_profile_memory_on_the_cpu_records_nothing_and_says_so_once(tmp_path):
    settings = dataclasses.replace(SETTINGS, out_dir=tmp_path, profile_memory=True, checkpoint_every=0)
    with pytest.warns(learning.TrainingWarning, match=r"profile_memory: cpu0 report no memory statistics") as caught:
        _, last = training.run(logging(), TASK, settings)
    assert len(caught) == 1 and not [k for k in last if k.startswith("memory/")]


def test_eval_seconds_is_converted_at_the_task_s_control_rate(monkeypatch):
    # mjzoo.control_dt measures a step of the task (a compile of MJX's step: ~15 s here).
    monkeypatch.setattr(training, "control_dt", lambda task: 0.02 if task is TASK else None)
    _, last = training.run(logging(), TASK, dataclasses.replace(SETTINGS, eval_seconds=5.0))
    assert last["eval/return"] == 250.0  # the counter's evaluation returns its step count; 5 / 0.02 = 249.99...


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"eval_every": -1}, "eval_every=-1 is invalid; expected an int >= 0 or None"),
        ({"eval_every": 1.5}, "eval_every=1.5 is invalid; expected an int"),
        ({"eval_every_seconds": 0}, "eval_every_seconds=0 is invalid; expected a finite number > 0"),
        ({"eval_first_seconds": -1.0}, "eval_first_seconds=-1.0 is invalid; expected a finite number >= 0"),
        ({"eval_first_seconds": "1"}, "eval_first_seconds='1' is invalid; expected a finite number"),
        ({"eval_every_seconds": float("inf")}, "eval_every_seconds=inf is invalid; expected a finite number"),
        ({"video_every": -2}, "video_every=-2 is invalid; expected an int >= 0"),
        ({"video_every": 2, "video": False}, "video_every=2 is invalid; expected 0 with video=False"),
        ({"log_every": 0}, "log_every=0 is invalid; expected an int >= 1"),
        ({"log_every": True}, "log_every=True is invalid; expected an int"),
        ({"eval_seconds": -0.5}, "eval_seconds=-0.5 is invalid; expected a finite number > 0"),
        ({"eval_steps": 10, "eval_seconds": 1.0}, "eval_seconds=1.0 is invalid; expected None with eval_steps: both"),
        ({"updates_per_chunk": 0}, "updates_per_chunk=0 is invalid; expected an int >= 1"),
        (
            {"render": {"width": 64}},
            "render={'width': 64} is invalid; expected a mjzoo.harness.rendering.RenderConfig",
        ),
    ],
)
def test_each_invalid_setting_is_named(fields, message):
    with pytest.raises(ValueError, match=f"^training.Settings: {re.escape(message)}"):
        training.Settings(**fields)


def test_numpy_numbers_are_kept_as_python_ones_for_config_json():
    settings = training.Settings(eval_every=np.int64(3), eval_every_seconds=np.float32(2.5))
    assert type(settings.eval_every) is int and type(settings.eval_every_seconds) is float


def test_config_json_holds_the_settings_and_the_cli_reads_it_back(tmp_path):
    render = rendering.RenderConfig(width=64, height=48, lookat=(0.0, 0.0, 1.0))
    settings = dataclasses.replace(SETTINGS, out_dir=tmp_path, render=render, eval_every_seconds=60.0)
    training.run(logging(), TASK, settings)
    _, info = runs.read_run(tmp_path)
    saved = info["settings"]
    assert saved["render"]["lookat"] == [0.0, 0.0, 1.0] and saved["eval_every_seconds"] == 60.0
    assert rendering.RenderConfig(**saved["render"]) == render  # JSON's lists become tuples again
    saved = {**saved, "out_dir": Path(saved["out_dir"]), "render": rendering.RenderConfig(**saved["render"])}
    assert training.Settings(**saved) == settings


# In a fresh process: MuJoCo reads MUJOCO_GL once, at import.
VIDEO_SCRIPT = """
import dataclasses, json, sys
from pathlib import Path
from typing import Any, NamedTuple
import jax.numpy as jnp
from mjzoo import learning
from mjzoo.harness import rendering, training
sys.path.insert(0, sys.argv[2])
import test_training as t

class Data(NamedTuple):  # what rendering reads of a trajectory: next_state.data's leaves, [T, ...]
    time: Any
    qpos: Any
    mocap_pos: Any
    mocap_quat: Any

class State(NamedTuple):  # and what it reads to end the video at the first episode
    data: Data
    terminated: Any
    truncated: Any
    layers: Any = None

class Trajectory(NamedTuple):
    next_state: State

def evaluate(task, s, key, n, steps):
    qpos = jnp.full((4, 1), 0.02) * s.updates  # each evaluation's video differs (the box in view)
    data = Data(jnp.arange(4) * 0.02, qpos, jnp.zeros((4, 0, 3)), jnp.zeros((4, 0, 4)))
    return learning.Evaluation(jnp.full(n, steps, jnp.float32), jnp.full(n, steps), Trajectory(State(data, jnp.zeros(4), jnp.zeros(4))))

algorithm = t.counter(evaluate=evaluate)
out = Path(sys.argv[1])
for chunks in (5, 4):  # the final evaluation is not (5) or is (4) one of video_every's
    settings = dataclasses.replace(t.SETTINGS, out_dir=out / str(chunks), video=True, video_every=2, eval_every=1,
                                   render=rendering.RenderConfig(width=64, height=48))
    training.run(algorithm._replace(num_updates=chunks), t.TASK, settings)
print(json.dumps(sorted(str(p.relative_to(out)) for p in out.rglob("*.mp4"))))
"""


@pytest.mark.skipif(not egl_installed(), reason="no EGL to render with")
def test_video_every_writes_a_video_every_n_evaluations(tmp_path):
    result = subprocess.run(
        [sys.executable, "-c", VIDEO_SCRIPT, str(tmp_path), str(Path(__file__).parent)],
        env={**os.environ, "MUJOCO_GL": "egl"},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        close_fds=False,  # lets Python use posix_spawn: no fork of this multithreaded (JAX) process
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout.splitlines()[-1]) == [
        "4/eval.mp4",
        "4/videos/eval_20.mp4",
        "4/videos/eval_40.mp4",
        "5/eval.mp4",
        "5/videos/eval_20.mp4",
        "5/videos/eval_40.mp4",
    ]
    assert (tmp_path / "4/eval.mp4").read_bytes() == (tmp_path / "4/videos/eval_40.mp4").read_bytes()  # a copy
    assert (tmp_path / "5/eval.mp4").read_bytes() != (tmp_path / "5/videos/eval_40.mp4").read_bytes()


def test_a_run_on_a_cpu_says_its_rate_and_how_long_it_will_take(tmp_path, capsys):
    """One printed line (not a warning) after the first chunk that ran without compiling
    (the second): its rate (1 update of 10 env steps in the fake clock's 10 s) and the
    whole run's 40 steps at that rate."""
    clock = FakeClock()
    settings = dataclasses.replace(SETTINGS, progress=True, eval_every=0, checkpoint_every=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        training.run(logging(4), TASK, settings, clock=clock, hooks=clock.hooks)
    notes = [line for line in capsys.readouterr().out.splitlines() if line.startswith("training on a CPU")]
    assert notes == [
        "training on a CPU: 1 env-steps/s, so 40 steps take about 40 s; "
        "training belongs on a GPU (mjzoo uses one wherever JAX finds it)"
    ]
    quiet, clock = dataclasses.replace(settings, progress=False), FakeClock()
    training.run(logging(4), TASK, quiet, clock=clock, hooks=clock.hooks)
    assert "training on a CPU" not in capsys.readouterr().out
