"""The API's routes, one module per resource; app.api_router() puts them under /api/v1.

Must not import service.cli nor simulators; a route reaches the bench through service.bench_control."""
