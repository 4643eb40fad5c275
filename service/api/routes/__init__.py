"""The API's routes, one module per resource; app.api_router() puts them under /api/v1."""
