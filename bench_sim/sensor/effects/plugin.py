"""Your own effect: a function of yours, named by import path, at a point of the signal path.

.. code-block:: toml

    [sensor.effects.gamma]
    kind = "plugin"
    function = "my_effects.py:gamma_response"   # a file (relative to this config) or "package.module:name"
    point = "charge"                            # charge, analog or digital
    truth = "monotone"                          # or "none"
    args = { gamma = 0.95 }

The contract of the function ``f(x, *, rng, **args) -> array``:

- ``x``: a float64 array of the reads at the point (``charge``: electrons after the full-well
  clip [e-]; ``analog``: the analog values [DN]; ``digital``: the raw values [DN], whole numbers),
  of shape (frames, rows, columns) when the chain draws; it must return an array of the same
  shape and a real dtype, finite (and ``>= 0`` at ``charge``). It may change ``x`` in place.
- ``rng``: the :class:`numpy.random.Generator` to draw any random number from (its own stream
  per chunk of frames: never ``numpy.random``'s global state, or the run is not reproducible).
- ``args``: the ``args`` table, as keyword arguments.
- ``truth = "monotone"`` (``charge`` only) declares the function a deterministic, non-decreasing
  map of the charge: the truth integrates through it (``mean_dn`` and ``noise_std_dn`` stay
  exact; ``linear_dn`` takes its secant slope over the first per cent of the full well). Checked
  on a grid of 0 .. full well before anything runs.
- ``truth = "none"``: the function's effect on a read is unknown; every output then says its truth
  is not exact (``truth_exact = false`` on every truth variable, with the effect named).

Every problem (an import error, a wrong signature, a wrong shape or dtype, NaN or negative
electrons, a response that falls) is one line naming ``sensor.effects.<name>``, before anything
runs: the function is called once on a small probe of the point's range when the chain is built.
The function is imported in every process that runs a pass (Dask workers too), by the same path.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import inspect
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.base import Effect, ReadLaw, Response, State, check_block

__all__ = ["EFFECT", "Plugin", "load_function"]


class PluginParams(BaseModel):
    """Parameters of ``kind = "plugin"``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    function: str = Field(
        description="'path/to/file.py:name' (relative to the config) or 'package.module:name'"
    )
    point: Literal["charge", "analog", "digital"] = Field(
        description="where it acts: charge, analog or digital"
    )
    truth: Literal["monotone", "none"] = Field(
        "none", description="monotone: a deterministic non-decreasing map of the charge (exact truth); none"
    )
    args: dict[str, Any] = Field(default_factory=dict, description="keyword arguments of the function")


@functools.cache
def _module(target: str) -> Any:
    """The module of ``target``: a ``.py`` file (imported under a name of its own) or a dotted name."""
    if target.endswith(".py"):
        path = Path(target).expanduser().resolve()
        if not path.is_file():
            raise FileNotFoundError(f"no such file {path}")
        name = "bench_sim_plugin_" + hashlib.sha1(str(path).encode()).hexdigest()[:12]
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise ImportError(f"cannot load {path}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
        return module
    return importlib.import_module(target)


def load_function(spec: str, where: str) -> Callable[..., Any]:
    """The function named by ``spec`` (``target:name``); one line naming ``where`` otherwise."""
    target, sep, attr = spec.rpartition(":")
    if not sep or not target or not attr.isidentifier():
        raise BenchSimError(
            f"{where} = {spec!r}: expected 'path/to/file.py:function' or 'package.module:function'"
        )
    try:
        module = _module(target)
    except Exception as exc:  # the user's module: anything it raises while importing
        reason = " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
        raise BenchSimError(f"{where} = {spec!r}: cannot import {target} ({reason})") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise BenchSimError(f"{where} = {spec!r}: {target} has no function {attr!r}")
    return fn


class Plugin(Effect):
    """A user's function at a point of the signal path (module docstring)."""

    kind = "plugin"
    summary = "your own function at the charge, analog or digital point (its truth declared or not)"
    Params = PluginParams

    def __init__(self, name: str, params: PluginParams, sensor: SensorConfig) -> None:
        super().__init__(name, params, sensor)
        self.p = params
        self.where = f"sensor.effects.{name}"
        if params.truth == "monotone" and params.point != "charge":
            raise BenchSimError(
                f"{self.where}.truth = 'monotone': only a response of the charge (point = "
                "'charge') can declare it; use truth = 'none'"
            )

    @functools.cached_property
    def function(self) -> Callable[..., Any]:
        """The user's function (imported on first use in each process)."""
        return load_function(self.p.function, f"{self.where}.function")

    @property
    def temporal(self) -> bool:
        return True

    def _call(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        try:
            return self.function(x, rng=rng, **self.p.args)
        except BenchSimError:
            raise
        except Exception as exc:  # the user's code
            reason = " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
            raise BenchSimError(f"{self.where} ({self.p.function}): raised {reason}") from None

    def _probe(self) -> np.ndarray:
        s = self.sensor
        if self.p.point == "charge":
            return np.linspace(0.0, s.full_well_e, 60).reshape(2, 3, 10)
        if self.p.point == "analog":
            return np.linspace(s.black_offset_dn, s.pixel_saturation_dn, 60).reshape(2, 3, 10)
        return np.round(np.linspace(0.0, s.pixel_saturation_dn, 60)).reshape(2, 3, 10)

    def check(self) -> None:
        """Import the function, check its signature and call it on a probe (module docstring)."""
        fn = self.function
        try:
            inspect.signature(fn).bind(np.zeros(1), rng=np.random.default_rng(0), **self.p.args)
        except TypeError as exc:
            raise BenchSimError(
                f"{self.where}.function = {self.p.function!r}: wrong signature ({exc}); "
                "expected f(x, *, rng, **args) with the args table's keys"
            ) from None
        except ValueError:
            pass  # a builtin without a signature: the probe call decides
        probe = self._probe()
        out = self._call(probe.copy(), np.random.default_rng(0))
        check_block(out, probe.shape, self.where, self.p.point == "charge")
        if self.p.truth == "monotone":
            self._check_monotone()

    def _check_monotone(self) -> None:
        grid = np.linspace(0.0, self.sensor.full_well_e, 2049)
        a = np.asarray(self._call(grid.copy(), np.random.default_rng(1)), dtype=np.float64)
        b = np.asarray(self._call(grid.copy(), np.random.default_rng(2)), dtype=np.float64)
        check_block(a, grid.shape, self.where, True)
        if not np.array_equal(a, b):
            raise BenchSimError(
                f"{self.where}: truth = 'monotone' but two calls on the same charge differ "
                "(it draws random numbers): declare truth = 'none'"
            )
        falls = np.flatnonzero(np.diff(a) < 0)
        if falls.size:
            e = grid[falls[0]]
            raise BenchSimError(
                f"{self.where}: truth = 'monotone' but the response falls after {e:g} e-; "
                "it must be non-decreasing over 0 .. full well"
            )

    def _at(self, point: str, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return self._call(x, rng) if self.p.point == point else x

    def charge(self, e: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        return self._at("charge", e, rng)

    def analog(self, y: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        return self._at("analog", y, rng)

    def digital(self, v: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        return self._at("digital", v, rng)

    @property
    def truth_note(self) -> str | None:
        if self.p.truth == "none":
            return f"{self.name}: plug-in {self.p.function} at {self.p.point} declares no truth"
        return None

    def law(self, law: ReadLaw, state: State) -> ReadLaw:
        if self.p.truth == "none":
            return law  # its effect on a read is unknown: the truth_note says so
        fixed_rng = np.random.default_rng(0)

        def response(e: np.ndarray) -> np.ndarray:
            return np.asarray(self._call(np.array(e, dtype=np.float64), fixed_rng), dtype=np.float64)

        h = 0.01 * self.sensor.full_well_e
        slope0 = float(response(np.array([h]))[0] - response(np.array([0.0]))[0]) / h
        return law.with_(responses=(*law.responses, Response(response, slope0, f"{self.name} (plug-in)")))


EFFECT = Plugin
