"""Mitsuba / Dr.Jit variant choice: CUDA when a GPU works, else LLVM with a working libLLVM,
else a scalar variant (with a warning).

Dr.Jit 1.5's LLVM backend aborts the *whole process* (``LLVM ERROR: Cannot select: fminimum``)
with Debian 12's libLLVM 15 and 16, while libLLVM 19 works. So no candidate library is ever
tried in this process: each is probed in a child process that runs a small kernel using
``dr.minimum`` (the operation that trips old LLVMs), and the verdict is cached on disk keyed by
the library's path, size, mtime and the Dr.Jit version. ``DRJIT_LIBLLVM_PATH`` is set before
Mitsuba is first imported.

A forced choice is forced: ``render.variant`` or ``BENCH_SIM_VARIANT`` naming a kind or a variant
that does not exist, or a backend that cannot run here, is a one-line
:class:`~bench_sim.errors.BenchSimError` (never a silent fallback); only ``"auto"`` falls back.
A probe cache that cannot be used (unreadable, not JSON, or JSON of another shape) is ignored
and rewritten.

Nothing in this module imports mitsuba or drjit at module import time.
"""

from __future__ import annotations

import glob
import json
import os
import re
import subprocess
import sys
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from bench_sim.config.variants import check_variant_name, mitsuba_variants
from bench_sim.errors import BenchSimError
from bench_sim.io.interrupts import deferred_interrupts

__all__ = [
    "BackendChoice",
    "ProbeResult",
    "llvm_candidates",
    "probe_llvm",
    "probe_cuda",
    "choose_backend",
    "select_backend",
    "init_mitsuba",
    "variant_for",
    "mitsuba_variants",
    "resolve_preference",
    "check_variant_name",
    "cache_folder",
]

ENV_VARIANT = "BENCH_SIM_VARIANT"

ENV_LLVM = "DRJIT_LIBLLVM_PATH"
#: Child-process probe: import drjit with the candidate library and run a kernel with
#: dr.minimum/dr.maximum on floats (LLVM's fminimum intrinsic), then print a marker.
_LLVM_PROBE = (
    "import drjit as dr\n"
    "from drjit.llvm import Float\n"
    "assert dr.has_backend(dr.JitBackend.LLVM), 'no LLVM backend'\n"
    "x = Float([1.0, -2.0, 3.5])\n"
    "y = dr.minimum(x, Float(0.5)) + dr.maximum(x, Float(0.0)) * 2\n"
    "dr.eval(y)\n"
    "assert abs(sum(y.numpy().tolist()) - 8.0) < 1e-5, 'wrong kernel result'\n"
    "print('BENCH_SIM_LLVM_OK')\n"
)
_CUDA_PROBE = (
    "import drjit as dr\n"
    "assert dr.has_backend(dr.JitBackend.CUDA), 'no CUDA backend'\n"
    "from drjit.cuda import Float\n"
    "y = dr.minimum(Float([1.0, -2.0]), Float(0.5))\n"
    "dr.eval(y)\n"
    "print('BENCH_SIM_CUDA_OK')\n"
)


@dataclass(frozen=True)
class ProbeResult:
    """Outcome of probing one backend in a child process."""

    ok: bool
    detail: str


@dataclass
class BackendChoice:
    """The chosen Mitsuba variant and why."""

    variant: str
    kind: str  # "cuda", "llvm" or "scalar"
    llvm_path: str | None
    reason: str
    probes: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {
            "variant": self.variant,
            "kind": self.kind,
            "llvm_path": self.llvm_path,
            "reason": self.reason,
            "probes": dict(self.probes),
        }


def _llvm_version_key(path: str) -> tuple[int, ...]:
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)(?:\.(\d+))?", os.path.basename(path))
    if not m:
        return (0,)
    return tuple(int(g) for g in m.groups() if g is not None)


def llvm_candidates(extra: Sequence[str] = ()) -> list[str]:
    """Candidate libLLVM shared libraries, newest first, de-duplicated by real path.

    ``DRJIT_LIBLLVM_PATH`` (if set) and ``extra`` come first, in that order.
    """
    found: list[str] = []
    env = os.environ.get(ENV_LLVM)
    if env:
        found.append(env)
    found.extend(extra)
    patterns = [
        "/usr/lib/*-linux-gnu/libLLVM*.so*",
        "/usr/lib/llvm-*/lib/libLLVM*.so*",
        "/usr/lib64/libLLVM*.so*",
        "/usr/local/lib/libLLVM*.so*",
        "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
    ]
    globbed: list[str] = []
    for pat in patterns:
        globbed.extend(glob.glob(pat))
    globbed.sort(key=_llvm_version_key, reverse=True)
    found.extend(globbed)
    seen: set[str] = set()
    out: list[str] = []
    for p in found:
        real = os.path.realpath(p)
        if real in seen or not os.path.exists(real):
            continue
        seen.add(real)
        out.append(p)
    return out


def _drjit_version() -> str:
    try:
        return version("drjit")
    except PackageNotFoundError:
        return "missing"


def cache_folder() -> Path:
    """bench_sim's cache folder on this machine: ``$BENCH_SIM_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/bench_sim``, else ``~/.cache/bench_sim`` (the backend probes' verdicts,
    the fast engine's records)."""
    root = os.environ.get("BENCH_SIM_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "bench_sim"
    )
    return Path(root)


def _cache_file() -> Path:
    return cache_folder() / "backend_probes.json"


def _cache_key(kind: str, path: str | None) -> str:
    if path is None:
        return f"{kind}|drjit={_drjit_version()}"
    try:
        st = os.stat(os.path.realpath(path))
        ident = f"{os.path.realpath(path)}|{st.st_size}|{int(st.st_mtime)}"
    except OSError:
        ident = path
    return f"{kind}|{ident}|drjit={_drjit_version()}"


def _load_cache() -> dict[str, Any]:
    """The probe cache; ``{}`` when it is missing, unreadable, not JSON or not a JSON object."""
    try:
        data = json.loads(_cache_file().read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _cached(key: str) -> ProbeResult | None:
    """The cached verdict under ``key``, or ``None`` if absent or not of the shape
    ``{"ok": bool, "detail": str}`` (such an entry is probed again and overwritten)."""
    hit = _load_cache().get(key)
    if isinstance(hit, dict) and isinstance(hit.get("ok"), bool) and isinstance(hit.get("detail"), str):
        return ProbeResult(hit["ok"], hit["detail"] + " (cached)")
    return None


def _store_cache(key: str, result: ProbeResult) -> None:
    path = _cache_file()
    data = _load_cache()
    data[key] = {"ok": result.ok, "detail": result.detail}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
        os.replace(tmp, path)
    except OSError:  # a read-only home must not stop a run
        pass


Runner = Callable[..., subprocess.CompletedProcess]


def _run_probe(
    code: str, env_extra: dict[str, str], marker: str, runner: Runner, timeout_s: float
) -> ProbeResult:
    env = dict(os.environ)
    env.update(env_extra)
    try:
        proc = runner(
            [sys.executable, "-c", code],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        return ProbeResult(False, f"probe timed out after {timeout_s:.0f} s")
    except OSError as exc:
        return ProbeResult(False, f"probe could not start: {exc}")
    if proc.returncode == 0 and marker in (proc.stdout or ""):
        return ProbeResult(True, "probe kernel ran")
    text = ((proc.stderr or "") + (proc.stdout or "")).strip().splitlines()
    last = next((ln for ln in reversed(text) if ln.strip()), "")
    if "Cannot select" in (proc.stderr or ""):
        last = next(ln for ln in text if "Cannot select" in ln)
    how = f"exit status {proc.returncode}" if proc.returncode >= 0 else f"signal {-proc.returncode}"
    return ProbeResult(False, f"probe failed ({how}): {last[:200]}")


def probe_llvm(
    path: str,
    *,
    runner: Runner = subprocess.run,
    use_cache: bool = True,
    timeout_s: float = 120.0,
) -> ProbeResult:
    """Probe whether Dr.Jit's LLVM backend works with the library at ``path``.

    The probe runs in a child process, so a library that makes LLVM abort kills only the child.
    Verdicts are cached on disk (``$BENCH_SIM_CACHE_DIR`` or ``~/.cache/bench_sim``).
    """
    key = _cache_key("llvm", path)
    if use_cache and (hit := _cached(key)) is not None:
        return hit
    result = _run_probe(_LLVM_PROBE, {ENV_LLVM: path}, "BENCH_SIM_LLVM_OK", runner, timeout_s)
    if use_cache:
        _store_cache(key, result)
    return result


def probe_cuda(
    *, runner: Runner = subprocess.run, use_cache: bool = True, timeout_s: float = 120.0
) -> ProbeResult:
    """Probe whether Dr.Jit's CUDA backend works (a GPU and driver are present), in a child."""
    if not (glob.glob("/dev/nvidia*") or glob.glob("/usr/lib/*-linux-gnu/libcuda.so*")):
        return ProbeResult(False, "no NVIDIA device or driver library found")
    key = _cache_key("cuda", None)
    if use_cache and (hit := _cached(key)) is not None:
        return hit
    result = _run_probe(_CUDA_PROBE, {}, "BENCH_SIM_CUDA_OK", runner, timeout_s)
    if use_cache:
        _store_cache(key, result)
    return result


def variant_for(kind: str, mode: str = "mono") -> str:
    """Mitsuba variant name for a backend kind and colour mode.

    The pip wheel has no ``scalar_mono``: the scalar fallback for mono is ``scalar_rgb`` (the
    scene is gray, so the channels are equal and one of them is the mono value).
    """
    if kind == "scalar":
        return "scalar_spectral" if mode == "spectral" else "scalar_rgb"
    return f"{kind}_ad_{mode}"


def resolve_preference(config_variant: str = "auto") -> tuple[str, str]:
    """The backend preference and where it comes from: ``render.variant`` unless it is
    ``"auto"``, then the environment variable ``BENCH_SIM_VARIANT``, else ``"auto"``.

    Returns ``(preference, source)`` with ``source`` the name to quote in messages.
    """
    if config_variant != "auto":
        return config_variant, "render.variant"
    env = os.environ.get(ENV_VARIANT)
    if env is not None and env.strip() not in ("", "auto"):
        return env.strip(), ENV_VARIANT
    return "auto", "render.variant"


def choose_backend(
    prefer: str = "auto",
    mode: str = "mono",
    *,
    llvm_probe: Callable[[str], ProbeResult] | None = None,
    cuda_probe: Callable[[], ProbeResult] | None = None,
    candidates: Callable[[], list[str]] | None = None,
    source: str | None = None,
) -> BackendChoice:
    """Choose a variant: CUDA if it works, else LLVM with the first library that passes its
    probe, else scalar (with a warning).

    Parameters
    ----------
    prefer
        ``"auto"``, a backend kind (``"cuda"``, ``"llvm"``, ``"scalar"``) or a full variant name.
        Environment variable ``BENCH_SIM_VARIANT`` overrides ``"auto"``. Anything but ``"auto"``
        is forced: if that backend cannot run here, :class:`BenchSimError` says why (one line).
    mode
        ``"mono"`` (default), ``"rgb"`` or ``"spectral"``.
    llvm_probe, cuda_probe, candidates
        The probes and the library search (default: :func:`probe_llvm`, :func:`probe_cuda`,
        :func:`llvm_candidates`).
    source
        Where ``prefer`` came from, for messages (default: ``render.variant``, or
        ``BENCH_SIM_VARIANT`` when the environment supplied it).
    """
    llvm_probe = llvm_probe or probe_llvm
    cuda_probe = cuda_probe or probe_cuda
    candidates = candidates or llvm_candidates
    if prefer == "auto":
        prefer, env_source = resolve_preference("auto")
        source = source or env_source
    source = source or "render.variant"
    check_variant_name(prefer, mode, source)
    probes: dict[str, str] = {}
    explicit_variant = prefer if "_" in prefer else None
    wanted = prefer.split("_", 1)[0] if explicit_variant else prefer
    forced = f"{source} = {prefer!r}"

    if wanted in ("auto", "cuda"):
        res = cuda_probe()
        probes["cuda"] = res.detail
        if res.ok:
            return BackendChoice(explicit_variant or variant_for("cuda", mode), "cuda", None,
                                 "CUDA backend works", probes)
        if wanted == "cuda":
            raise BenchSimError(
                f"{forced}: the CUDA backend cannot run here ({res.detail}); use 'auto' "
                "(CUDA, else LLVM, else scalar) or 'llvm'"
            )
    if wanted in ("auto", "llvm"):
        variant = explicit_variant or variant_for("llvm", mode)
        llvm = _first_working_llvm(candidates(), llvm_probe, probes, variant)
        if llvm is not None:
            return llvm
        if wanted == "llvm":
            tried = "; ".join(f"{p}: {d}" for p, d in probes.items() if p != "cuda") or "none found"
            raise BenchSimError(
                f"{forced}: no libLLVM passed the probe ({tried[:300]}); install Debian's libllvm19 "
                "or use 'auto' or 'scalar'"
            )
    reason = "no working CUDA device and no libLLVM passed the probe"
    if wanted == "scalar":
        reason = f"scalar variant requested ({source})"
    else:
        warnings.warn(
            f"bench_sim: {reason}; falling back to the slow scalar variant "
            "(install Debian's libllvm19 for the LLVM backend)",
            RuntimeWarning,
            stacklevel=2,
        )
    return BackendChoice(
        explicit_variant if wanted == "scalar" and explicit_variant else variant_for("scalar", mode),
        "scalar",
        None,
        reason,
        probes,
    )


def _first_working_llvm(
    paths: Sequence[str], probe: Callable[[str], ProbeResult], probes: dict[str, str], variant: str
) -> BackendChoice | None:
    """The LLVM choice with the first library of ``paths`` that passes ``probe``, or ``None``;
    each verdict is recorded in ``probes`` (path -> ``ok: ...`` / ``rejected: ...``)."""
    for path in paths:
        res = probe(path)
        probes[path] = ("ok: " if res.ok else "rejected: ") + res.detail
        if res.ok:
            return BackendChoice(variant, "llvm", path, f"libLLVM at {path} passed the probe", probes)
    return None


_ACTIVE: BackendChoice | None = None


def select_backend(prefer: str = "auto", mode: str = "mono") -> BackendChoice:
    """Choose the backend for this process without importing Mitsuba (the up-front check of a
    command): once per process, again only when a different kind is forced later. Sets
    ``DRJIT_LIBLLVM_PATH`` for the chosen library. Raises :class:`BenchSimError` (one line) for
    an unknown name or a forced backend that cannot run."""
    global _ACTIVE
    prefer, source = resolve_preference(prefer)
    check_variant_name(prefer, mode, source)
    wanted_kind = prefer.split("_", 1)[0]
    if _ACTIVE is not None and wanted_kind in ("auto", _ACTIVE.kind):
        choice = _ACTIVE
        wanted = prefer if "_" in prefer else variant_for(choice.kind, mode)
        if wanted != choice.variant:
            choice = BackendChoice(wanted, choice.kind, choice.llvm_path, choice.reason, choice.probes)
            _ACTIVE = choice
        return choice
    choice = choose_backend(prefer, mode, source=source)
    if choice.llvm_path is not None:  # the probed library, even over a user's failing one
        os.environ[ENV_LLVM] = choice.llvm_path
    _ACTIVE = choice
    return choice


def init_mitsuba(prefer: str = "auto", mode: str = "mono") -> tuple[Any, BackendChoice]:
    """Choose the backend (:func:`select_backend`), import Mitsuba and set its variant.
    Returns ``(mitsuba module, choice)``.

    A later call with another mode switches the variant on the same backend kind.
    """
    if _ACTIVE is None and "mitsuba" in sys.modules and os.environ.get(ENV_LLVM) is None:
        warnings.warn(
            "bench_sim: mitsuba was imported before the backend was chosen", RuntimeWarning, stacklevel=2
        )
    choice = select_backend(prefer, mode)
    # Ctrl-C is held while the extension loads: an import of Mitsuba/Dr.Jit cut short can abort
    # the interpreter at exit or leave the import lock held (bench_sim.io.interrupts)
    with deferred_interrupts():
        import mitsuba as mi

        if mi.variant() != choice.variant:
            mi.set_variant(choice.variant)
    return mi, choice


def versions() -> dict[str, str]:
    """Versions of bench_sim and its core libraries."""
    out = {"python": sys.version.split()[0]}
    for pkg in ("bench_sim", "mitsuba", "drjit", "numpy", "OpenEXR", "trimesh", "pydantic"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "missing"
    return out
