"""The service's one configuration object (pydantic-settings): ``RENDER_BUDGET_*`` environment variables,
overridden by the options actually given on the command line (:func:`load_settings`)."""

from __future__ import annotations

import ipaddress
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import platformdirs
from pydantic import Field, SecretStr, ValidationError, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

_REPO_ROOT = Path(__file__).resolve().parents[2]
ENV_PREFIX = "RENDER_BUDGET_"
MIN_TOKEN_LENGTH = 8
#: Host names a loopback service without a token answers to (any port): a page whose own name was made
#: to resolve to 127.0.0.1 (DNS rebinding) still sends that name, and is refused.
LOOPBACK_HOST_NAMES = frozenset({"127.0.0.1", "localhost", "[::1]"})


def default_data_dir() -> Path:
    """The project's var/ when running from a source checkout, else the user's data directory."""
    if (_REPO_ROOT / "pyproject.toml").is_file() and (_REPO_ROOT / "service").is_dir():
        return _REPO_ROOT / "var" / "service"
    return Path(platformdirs.user_data_dir("render-budget"))


def is_loopback(host: str) -> bool:
    """True for hosts that only this machine can reach (127.0.0.0/8, ::1, localhost)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def host_name(value: str) -> str:
    """The name part of a Host header or an allow-list entry, lower case, IPv6 literals in brackets:
    ``Example.com:80`` -> ``example.com``, ``[::1]:8765`` and ``::1`` -> ``[::1]``."""
    value = value.strip().lower()
    if value.startswith("["):
        return value.split("]", 1)[0] + "]"
    if value.count(":") > 1:  # a bare IPv6 literal
        return f"[{value}]"
    return value.rsplit(":", 1)[0] if ":" in value else value


class Settings(BaseSettings):
    """Where the service binds, keeps its data and sends its evaluations, and how much it accepts."""

    model_config = SettingsConfigDict(env_prefix=ENV_PREFIX, extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8765, ge=0, le=65535)
    data_dir: Path = Field(default_factory=default_data_dir)
    dask_scheduler: str | None = None
    dask_ship_scenes: bool = True  # send scene bytes to Dask workers (no shared disk needed)
    token: SecretStr | None = None
    # Host names accepted in the Host header ("*": any). Default: the loopback names when the service is
    # bound to loopback without a token, else any.
    allowed_hosts: Annotated[list[str] | None, NoDecode] = None
    # Limits at the edge.
    max_upload_bytes: int = Field(default=64 * 1024 * 1024, gt=0)
    max_body_bytes: int = Field(default=4 * 1024 * 1024, gt=0)
    body_read_timeout_s: float = Field(default=30.0, gt=0, le=3600)  # longest pause inside a request body
    max_path_frames: int = Field(default=20_000, gt=0)
    max_render_pixels: int = Field(default=1024 * 1024, gt=0)  # previews and /evaluate
    # Work.
    job_workers: int = Field(default=2, ge=1, le=64)
    # Local worker processes rendering a job's evaluations (1: in the job's own thread). Ignored when a
    # Dask scheduler is set.
    eval_workers: int = Field(default=1, ge=1, le=256)
    render_threads: int | None = Field(default=None, ge=1)
    scene_cache_size: int = Field(default=8, ge=1)
    store_cache_size: int = Field(default=64, ge=1)
    # The evaluation cache's size cap; least recently used evaluations go first (never a running job's).
    eval_cache_max_bytes: int = Field(default=2 * 1024**3, ge=64 * 1024)
    sse_poll_s: float = Field(default=0.1, gt=0, le=5)
    sse_keepalive_s: float = Field(default=15.0, gt=0)

    @field_validator("token")
    @classmethod
    def _token_long_enough(cls, v: SecretStr | None) -> SecretStr | None:
        if v is not None and len(v.get_secret_value().strip()) < MIN_TOKEN_LENGTH:
            raise ValueError(f"must be at least {MIN_TOKEN_LENGTH} non-blank characters")
        return v

    @field_validator("allowed_hosts", mode="before")
    @classmethod
    def _host_list(cls, v: Any) -> Any:
        if isinstance(v, str):  # RENDER_BUDGET_ALLOWED_HOSTS="a.example,b.example"
            v = [h for h in v.split(",") if h.strip()]
        if isinstance(v, list | tuple):
            return [h if h.strip() == "*" else host_name(h) for h in v if isinstance(h, str) and h.strip()]
        return v

    def check_bind(self) -> None:
        """Refuse a bind other machines can reach unless a token protects it."""
        if not is_loopback(self.host) and self.token is None:
            raise ValueError(
                f"refusing to bind {self.host!r} without a token: other machines could reach the service; "
                f"pass --token (or set {ENV_PREFIX}TOKEN), or bind 127.0.0.1"
            )

    def host_allow_list(self) -> frozenset[str] | None:
        """Host names to accept, or None for any."""
        if self.allowed_hosts is not None:
            names = frozenset(self.allowed_hosts)
            return None if "*" in names else names
        if self.token is None and is_loopback(self.host):
            return LOOPBACK_HOST_NAMES | {host_name(self.host)}
        return None


def load_settings(overrides: Mapping[str, Any] | None = None) -> Settings:
    """Settings from the environment, with ``overrides`` (the command-line options actually given) on
    top. A bad value raises ValueError with one line naming the setting, never its value."""
    try:
        return Settings(**dict(overrides or {}))
    except ValidationError as exc:
        problems = []
        for err in exc.errors(include_input=False, include_url=False):
            name = ".".join(str(p) for p in err["loc"]) or "settings"
            flag = f"--{name.replace('_', '-')} or " if name in (overrides or {}) else ""
            message = str(err["msg"]).removeprefix("Value error, ")
            problems.append(f"{name} ({flag}{ENV_PREFIX}{name.upper()}): {message}")
        raise ValueError("invalid setting " + "; ".join(problems)) from None
