"""bench_sim: a physically-based optical test-bench simulator for HDR push-broom imaging with
digital time-delay integration (DTDI).

Data flow (one direction): ``config -> rig -> render -> sensor -> fusion -> metrics -> experiments``.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bench_sim")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0+source"

__all__ = ["__version__", "simulate"]


def __getattr__(name: str):  # lazy: importing bench_sim stays cheap
    if name == "simulate":
        from bench_sim.workflows.simulate import simulate

        return simulate
    raise AttributeError(f"module 'bench_sim' has no attribute {name!r}")
