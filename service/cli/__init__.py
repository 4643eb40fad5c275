"""The `shockbench` command line: one module per group of subcommands, registered in main.py.

BLAS threads: the estimator's least-squares problems are tall and thin (thousands of rows, tens of
columns), where a second BLAS thread gains little, while on a 2-core bench PC the acquisition, the service
and the worker process share the cores. Under that contention OpenBLAS's spinning threads made the
normal-matrix product of a 24 000 x 45 system 100 times slower (1.29 s against 13.6 ms with one thread,
measured on this project's 2-core machine under load). So every process started through the command line
(and the worker and device processes it spawns, which inherit the environment) uses one BLAS thread,
unless the user's environment says otherwise. This must run before numpy is first imported, which is why
it lives in the package's __init__ and the package imports nothing else.


Must not import simulators except in service.cli.simulate (the offline vehicle simulation); a
simulated bench comes from service.simulated_bench."""

import os

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")
