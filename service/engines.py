"""Where the product's work runs: the four execution engines beside the service's event loop, what each
runs, and why it is a separate engine rather than one more task on the loop.

The service's event loop (uvicorn, asyncio) answers the API and only awaits: it never computes for longer
than a request's bookkeeping. Everything that takes longer runs in one of these:

1. **The worker process** (service.jobs.worker, owned by service.jobs.manager through
   service.jobs.process): identification, diagnosis and validation jobs, one at a time, in a spawned
   interpreter at a lower priority. Why a process: differential evolution and the doctor hold the
   interpreter lock for minutes and may crash or be killed on cancel; a process keeps the loop responsive,
   and its death fails one job instead of the service. It talks over a pipe in typed messages
   (service.jobs.messages).
2. **The bench thread** (service.bench_control.BenchController.start_sweep): one sweep at a time, with an
   asyncio loop of its own (daq.sweep.run.run_sweep) that drives the exciter and reads the lasers. Why a
   thread: acquisition is I/O bound and shares the live view and the emergency stop with the API in memory
   (a lock, no copy per sample); a loop of its own keeps device timing away from request handling.
3. **Dask** (service.reanalyse.run, `shockbench reanalyse`): an archive's recordings re-identified in
   parallel, on a LocalCluster of worker processes or a running scheduler. Why Dask: the same client code
   runs on one PC or a cluster, retries a task whose worker died and marks one that keeps killing workers
   as failed, and the run resumes from the results already stored.
4. **The doctor's thread pool** (estimator.doctor.diagnose, `DiagnoseOptions.workers` threads, inside
   whichever engine runs the diagnosis: the worker process, the CLI, or a Dask task). Why threads: the
   candidate effects' fits are independent, and their heavy parts (LAPACK solves, BLAS products) release
   the interpreter lock, so threads share the recording without copying it.

Two helpers are smaller: the input checker (service.api.input_check) reads uploads in one spawned process
so that parsing a large CSV never holds the loop's interpreter lock, and a simulated bench
(service.simulated_bench) runs its devices' loop in a thread of its own.

`ENGINES` lists the four with the module that starts each (tests check that they exist).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Engine:
    name: str
    module: str
    """The module that starts it."""
    runs: str
    why: str


ENGINES: tuple[Engine, ...] = (
    Engine(
        "worker process",
        "service.jobs.worker",
        "identify, diagnose and validate jobs, one at a time",
        "minutes of CPU under the interpreter lock, and a crash or a kill fails one job, not the service",
    ),
    Engine(
        "bench thread",
        "service.bench_control",
        "one sweep: exciter commands and laser acquisition on an asyncio loop of its own",
        "I/O bound, and shares the live view and the emergency stop with the API in memory",
    ),
    Engine(
        "Dask",
        "service.reanalyse.run",
        "an archive's recordings re-identified in parallel (`shockbench reanalyse`)",
        "one PC or a cluster with the same code, retries of dead workers, resumable",
    ),
    Engine(
        "doctor's thread pool",
        "estimator.doctor.diagnose",
        "the doctor's independent candidate fits",
        "their LAPACK and BLAS parts release the interpreter lock; threads share the recording",
    ),
)
