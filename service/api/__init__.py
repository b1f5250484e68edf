"""REST service over the optimiser and the Pareto store (FastAPI app, uvicorn server, durable jobs)."""

from .app import create_app
from .config import Settings

__all__ = ["Settings", "create_app"]
