"""The options of ``render-budget serve`` and ``python -m service.api.server``, in a module without web
dependencies: the CLI's other commands start fast, and the server imports them without importing the CLI
(no import cycle)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

SERVE_SETTINGS = ("host", "port", "data_dir", "dask_scheduler", "token", "eval_workers", "allowed_hosts")


def add_serve_arguments(parser: argparse.ArgumentParser) -> None:
    """The serve options. Settings options have no argparse default: only the ones given reach the
    service (:func:`serve_overrides`)."""
    given = argparse.SUPPRESS
    parser.add_argument("--host", default=given,
                        help="bind address (default 127.0.0.1; RENDER_BUDGET_HOST)")
    parser.add_argument("--port", type=int, default=given, help="port (default 8765; RENDER_BUDGET_PORT)")
    parser.add_argument("--data-dir", type=Path, default=given,
                        help="database and scene files (default: var/service in a checkout, else the user "
                             "data directory; RENDER_BUDGET_DATA_DIR)")
    parser.add_argument("--dask-scheduler", default=given, metavar="ADDR",
                        help="fan evaluations out to this Dask scheduler (RENDER_BUDGET_DASK_SCHEDULER)")
    parser.add_argument("--token", default=given,
                        help="bearer token, at least 8 non-blank characters; required for a non-loopback "
                             "bind (RENDER_BUDGET_TOKEN, which keeps it out of the process list)")
    parser.add_argument("--eval-workers", type=int, default=given, metavar="N",
                        help="local processes rendering a job's evaluations (default 1; ignored with Dask; "
                             "RENDER_BUDGET_EVAL_WORKERS)")
    parser.add_argument("--allowed-hosts", default=given, metavar="NAMES",
                        help="comma-separated host names the service answers to, '*' for any (default: "
                             "127.0.0.1, localhost and [::1] on a loopback bind without a token, else any; "
                             "RENDER_BUDGET_ALLOWED_HOSTS)")
    parser.add_argument("--log-level", default="info")


def serve_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The settings given on the command line (absent options leave the environment's values alone)."""
    return {name: getattr(args, name) for name in SERVE_SETTINGS if hasattr(args, name)}
