"""Jobs run in a worker process the service owns: messages, the kinds registry, the worker itself, and
the asyncio manager that queues jobs and restarts the worker."""
