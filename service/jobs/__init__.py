"""Jobs run in a worker process the service owns: the typed messages over its pipe, the kinds registry,
the worker itself, and the asyncio manager that queues jobs and restarts the worker. The worker process is
one of the product's execution engines (service.engines names them all).

Must not import service.api (the API uses the jobs, not the other way round) nor simulators."""
