"""The worker's messages and the job events are typed all the way (issue 32, item 5): every payload is a
checked field (a job's options and result are JSON documents, its progress a Progress), the messages still
pickle over the pipe and are built positionally, and what reaches the database and the API is the same
JSON as before. service.engines names the execution engines, each with the module that starts it."""

from __future__ import annotations

import asyncio
import importlib.util
import math
import pickle
from pathlib import Path

import pytest
from pydantic import ValidationError

from service import engines
from service.api.schemas import ProgressOut
from service.jobs.broker import EventBroker, JobClosingEvent, JobFinishedEvent, JobProgressEvent
from service.jobs.context import JobOutcome, finite_json
from service.jobs.messages import (
    CancelJob,
    JobCancelled,
    JobFailed,
    JobProgress,
    JobStarted,
    JobSucceeded,
    Progress,
    RunJob,
    Shutdown,
    WorkerExited,
    WorkerReady,
)
from service.store.jobs import JobRecord

RESULT = {"curves": [{"corner": "single", "force_N": [1.5, -2.0]}], "gap_m": None, "warnings": []}


def test_every_message_pickles_over_the_pipe_and_is_built_positionally() -> None:
    messages = [
        RunJob(7, "identify", "/data/r.csv", "/data/v.toml", "/data/out", {"solver": "de", "seed": 3}),
        CancelJob(7),
        Shutdown(),
        WorkerReady(1234),
        JobStarted(7),
        JobProgress(7, Progress("differential evolution", 1.25, 10, 3000, 0.5, 12.0)),
        JobSucceeded(7, RESULT, {"plot.png": "plot.png"}),
        JobFailed(7, "the recording has 3 samples"),
        JobCancelled(7),
        WorkerExited(2, -9),
    ]
    for message in messages:
        assert pickle.loads(pickle.dumps(message)) == message


def test_a_result_or_options_that_are_not_json_are_refused_where_they_are_made() -> None:
    not_json = "not a valid JSON value"
    with pytest.raises(ValidationError, match=f"JobSucceeded\n1.curve\n  input was {not_json}"):
        JobSucceeded(7, {"curve": object()})
    with pytest.raises(ValidationError, match=f"JobOutcome\n0.when\n  input was {not_json}"):
        JobOutcome({"when": {1, 2}})  # the job function's own outcome: checked in the worker that ran it
    with pytest.raises(ValidationError, match=f"RunJob\n5.seed\n  input was {not_json}"):
        RunJob(7, "identify", "r", "v", "o", {"seed": Path("x")})
    with pytest.raises(ValidationError, match=r"JobProgress\n1\.elapsed_s\n  Field required"):
        JobProgress(7, {"stage": "x"})  # type: ignore[arg-type]


def test_the_json_that_reaches_the_database_and_the_api_is_unchanged() -> None:
    progress = Progress("plotting", 2.5, 3000, 3000, 0.125, None)
    assert progress.as_dict() == {
        "stage": "plotting",
        "elapsed_s": 2.5,
        "generation": 3000,
        "generations": 3000,
        "best_objective": 0.125,
        "eta_s": None,
    }
    assert ProgressOut.of(progress) == ProgressOut.of(progress.as_dict())
    result = finite_json({"gap_m": math.nan, "force_N": (1.0, math.inf)})
    assert JobSucceeded(1, result).result == {"gap_m": None, "force_N": [1.0, None]}  # as stored
    assert JobOutcome(dict(RESULT)).result == RESULT


def test_a_listener_hears_typed_events_and_the_closing_last() -> None:
    async def scenario() -> list[object]:
        broker = EventBroker(queue_size=2)
        queue = broker.subscribe(5)
        record = JobRecord.__new__(JobRecord)  # the broker carries the record as it is, unread
        for generation in (1, 2):
            broker.publish(JobProgressEvent(5, Progress("de", 0.1, generation, 9)))
        broker.publish(JobFinishedEvent(5, record))  # the oldest progress makes room
        broker.close()
        return [queue.get_nowait() for _ in range(queue.qsize())]

    heard = asyncio.run(scenario())
    assert [type(event) for event in heard] == [JobFinishedEvent, JobClosingEvent]


def test_the_engines_module_names_each_engine_and_where_it_starts() -> None:
    text = engines.__doc__ or ""
    assert [engine.name for engine in engines.ENGINES] == [
        "worker process",
        "bench thread",
        "Dask",
        "doctor's thread pool",
    ]
    for engine in engines.ENGINES:
        assert engine.name.lower() in text.lower() and engine.module in text
        assert importlib.util.find_spec(engine.module) is not None, engine.module
