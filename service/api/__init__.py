"""The bench service's HTTP API (FastAPI): create_app(settings) and its settings.

Must not import service.cli (the commands start the API, not the other way round) nor simulators."""

from service.api.app import Services, create_app, lifespan_factory
from service.api.settings import ServiceSettings

__all__ = ["ServiceSettings", "Services", "create_app", "lifespan_factory"]
