"""The installed version of bench_sim (one place; every output's provenance quotes it)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bench_sim")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0+source"

__all__ = ["__version__"]
