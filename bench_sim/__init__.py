"""bench_sim: a physically-based optical test-bench simulator for HDR push-broom imaging with
digital time-delay integration (DTDI).

Data flow (one direction): ``config -> rig -> render -> sensor -> fusion -> metrics -> measure ->
workflows -> cli``.

The public API:

* :func:`calibrate` - a sensor model fitted to a camera's photon-transfer data or EMVA 1288
  results, and its predicted DTDI dynamic range (:func:`bench_sim.workflows.calibrate.calibrate`);
* :func:`design` - which stages, fusion rule, word and timing to use for a camera and a scene,
  every candidate scored on the exact truth (:func:`bench_sim.workflows.design.run.run_design`);
* :func:`simulate` - any bench to its DTDI stage images with exact ground truth
  (:func:`bench_sim.workflows.simulate.simulate`);
* :func:`run_pass` - one pass, frames -> sensor -> DTDI -> stage images and their truth
  (:func:`bench_sim.pipeline.run_pass`);
* :func:`load_config` - a bench config from TOML (:func:`bench_sim.config.load_config`);
* :mod:`dataset` - reading a generated data set: ``bench_sim.dataset.open(DIR)``,
  ``bench_sim.dataset.iter_samples(DIR)``, ``iter_batches``, ``torch_dataset``, ``score_fusion``
  (the module :mod:`bench_sim.dataset`: ``from bench_sim.dataset import iter_batches`` works);
* ``__version__`` - the installed version (:mod:`bench_sim.version`).

The package itself imports nothing: each public name is resolved from its module (the table
:data:`PUBLIC`) the first time it is used (PEP 562), so ``import bench_sim.errors`` or
``bench_sim.cli``'s start-up pay only for what they import, and Ctrl-C during start-up is
handled by :mod:`bench_sim.__main__`. The dependencies stay visible: every module imports its own
at its top.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bench_sim import dataset
    from bench_sim.config import load_config
    from bench_sim.pipeline import run_pass
    from bench_sim.version import __version__
    from bench_sim.workflows.calibrate import calibrate
    from bench_sim.workflows.design.run import run_design as design
    from bench_sim.workflows.simulate import simulate

__all__ = ["__version__", "calibrate", "dataset", "design", "load_config", "run_pass", "simulate"]

#: public name -> (module, attribute; ``None`` for the module itself)
PUBLIC: dict[str, tuple[str, str | None]] = {
    "__version__": ("bench_sim.version", "__version__"),
    "calibrate": ("bench_sim.workflows.calibrate", "calibrate"),
    "dataset": ("bench_sim.dataset", None),
    "design": ("bench_sim.workflows.design.run", "run_design"),
    "load_config": ("bench_sim.config", "load_config"),
    "run_pass": ("bench_sim.pipeline", "run_pass"),
    "simulate": ("bench_sim.workflows.simulate", "simulate"),
}


def __getattr__(name: str) -> Any:
    if name not in PUBLIC:
        raise AttributeError(f"module 'bench_sim' has no attribute {name!r}")
    module, attr = PUBLIC[name]
    value = importlib.import_module(module)
    return value if attr is None else getattr(value, attr)


def __dir__() -> list[str]:
    return sorted(__all__)
