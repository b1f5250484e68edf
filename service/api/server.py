"""``render-budget serve``: run the REST service under uvicorn (127.0.0.1 unless a token protects it)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import uvicorn

from service.cli import add_serve_arguments

from .app import create_app
from .config import Settings


def run(host: str = "127.0.0.1", port: int = 8765, data_dir: str | Path | None = None,
        dask_scheduler: str | None = None, token: str | None = None, *, log_level: str = "info",
        eval_workers: int | None = None) -> None:
    """Serve until interrupted. Raises ValueError for a non-loopback bind without a token."""
    kwargs: dict[str, object] = {"host": host, "port": port, "dask_scheduler": dask_scheduler, "token": token}
    if eval_workers is not None:
        kwargs["eval_workers"] = eval_workers
    if data_dir is not None:
        kwargs["data_dir"] = Path(data_dir)
    settings = Settings(**kwargs)
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
        run(args.host, args.port, args.data_dir, args.dask_scheduler, args.token, log_level=args.log_level,
            eval_workers=args.eval_workers)
    except ValueError as exc:
        parser.exit(2, f"error: {exc}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
