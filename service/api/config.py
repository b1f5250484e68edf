"""The service's one configuration object (pydantic-settings: arguments, then RENDER_BUDGET_* variables)."""

from __future__ import annotations

import ipaddress
from pathlib import Path

import platformdirs
from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

_REPO_ROOT = Path(__file__).resolve().parents[2]


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


class Settings(BaseSettings):
    """Where the service binds, keeps its data and sends its evaluations, and how much it accepts."""

    model_config = SettingsConfigDict(env_prefix="RENDER_BUDGET_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8765, ge=0, le=65535)
    data_dir: Path = Field(default_factory=default_data_dir)
    dask_scheduler: str | None = None
    dask_ship_scenes: bool = True  # send scene bytes to Dask workers (no shared disk needed)
    token: SecretStr | None = None
    # Limits at the edge.
    max_upload_bytes: int = Field(default=64 * 1024 * 1024, gt=0)
    max_body_bytes: int = Field(default=4 * 1024 * 1024, gt=0)
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
    query_fast_path: bool = True  # serve store queries without FastAPI's routing layer (same answers)
    sse_poll_s: float = Field(default=0.1, gt=0, le=5)
    sse_keepalive_s: float = Field(default=15.0, gt=0)

    @field_validator("token")
    @classmethod
    def _token_not_blank(cls, v: SecretStr | None) -> SecretStr | None:
        if v is not None and len(v.get_secret_value().strip()) < 8:
            raise ValueError("token must be at least 8 non-blank characters")
        return v

    def check_bind(self) -> None:
        """Refuse a bind other machines can reach unless a token protects it."""
        if not is_loopback(self.host) and self.token is None:
            raise ValueError(
                f"refusing to bind {self.host!r} without a token: other machines could reach the service; "
                "pass --token (or set RENDER_BUDGET_TOKEN), or bind 127.0.0.1"
            )
