"""The bench service's HTTP API (FastAPI): create_app(settings) and its settings."""

from service.api.app import Services, create_app, lifespan_factory
from service.api.settings import ServiceSettings

__all__ = ["ServiceSettings", "Services", "create_app", "lifespan_factory"]
