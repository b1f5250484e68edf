"""``render-budget serve``: run the REST service under uvicorn (127.0.0.1 unless a token protects it)."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Mapping
from typing import Any

import uvicorn

from service.serve_options import add_serve_arguments, serve_overrides

from .app import create_app
from .config import load_settings


def run(overrides: Mapping[str, Any] | None = None, *, log_level: str = "info") -> None:
    """Serve until interrupted, with settings from ``RENDER_BUDGET_*`` variables and ``overrides`` (the
    command-line options given) on top. Raises ValueError for a bad setting or a non-loopback bind
    without a token."""
    settings = load_settings(overrides)
    settings.check_bind()
    logging.basicConfig(level=getattr(logging, log_level.upper(), logging.INFO),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=log_level,
                timeout_graceful_shutdown=10, access_log=False)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m service.api.server", description=__doc__)
    add_serve_arguments(parser)
    args = parser.parse_args(argv)
    try:
        run(serve_overrides(args), log_level=args.log_level)
    except ValueError as exc:
        parser.exit(2, f"error: {exc}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
