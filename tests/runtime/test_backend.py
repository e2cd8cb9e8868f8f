"""Variant choice: never let a bad libLLVM abort the process; tested without a broken library."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from bench_sim.runtime import backend
from bench_sim.runtime.backend import ProbeResult, choose_backend, probe_llvm, variant_for


def _fake_proc(returncode: int, stdout: str = "", stderr: str = ""):
    def runner(cmd, **kwargs):
        return subprocess.CompletedProcess(cmd, returncode, stdout, stderr)

    return runner


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("BENCH_SIM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("BENCH_SIM_VARIANT", raising=False)


def test_llvm_abort_in_child_is_a_rejection_not_a_crash(tmp_path):
    # what Debian 12's libLLVM 15/16 do: LLVM prints and the process dies of SIGABRT
    runner = _fake_proc(-6, stderr="LLVM ERROR: Cannot select: 0x55 f32 = fminimum 0x1, 0x2\n")
    res = probe_llvm("/fake/libLLVM-15.so", runner=runner)
    assert not res.ok
    assert "signal 6" in res.detail and "Cannot select" in res.detail


def test_a_real_child_that_aborts_leaves_the_parent_alive(tmp_path):
    """The probe runs in a real child process that aborts like LLVM does."""

    def aborting_runner(cmd, **kwargs):
        return subprocess.run([sys.executable, "-c", "import os; os.abort()"], **kwargs)

    res = probe_llvm("/fake/libLLVM-16.so", runner=aborting_runner)
    assert not res.ok and "signal" in res.detail


def test_probe_verdicts_are_cached_per_library():
    calls = []

    def runner(cmd, **kwargs):
        calls.append(kwargs["env"][backend.ENV_LLVM])
        return subprocess.CompletedProcess(cmd, 0, "BENCH_SIM_LLVM_OK\n", "")

    assert probe_llvm("/fake/libLLVM.so.19.1", runner=runner).ok
    again = probe_llvm("/fake/libLLVM.so.19.1", runner=runner)
    assert again.ok and "cached" in again.detail
    assert calls == ["/fake/libLLVM.so.19.1"]


def test_choice_prefers_cuda_then_first_working_llvm_then_scalar():
    ok, bad = ProbeResult(True, "fine"), ProbeResult(False, "Cannot select: fminimum")
    libs = ["/l/libLLVM-15.so", "/l/libLLVM.so.19.1"]
    verdict = {"/l/libLLVM-15.so": bad, "/l/libLLVM.so.19.1": ok}
    c = choose_backend(cuda_probe=lambda: ok, llvm_probe=verdict.__getitem__, candidates=lambda: libs)
    assert (c.variant, c.kind, c.llvm_path) == ("cuda_ad_mono", "cuda", None)
    c = choose_backend(cuda_probe=lambda: bad, llvm_probe=verdict.__getitem__, candidates=lambda: libs)
    assert (c.variant, c.llvm_path) == ("llvm_ad_mono", "/l/libLLVM.so.19.1")
    assert "rejected" in c.probes["/l/libLLVM-15.so"]
    with pytest.warns(RuntimeWarning, match="scalar"):
        c = choose_backend(cuda_probe=lambda: bad, llvm_probe=lambda p: bad, candidates=lambda: libs)
    assert (c.variant, c.kind) == ("scalar_rgb", "scalar")


def test_explicit_choices_and_bad_names():
    ok = ProbeResult(True, "fine")
    c = choose_backend(
        "llvm", "rgb", cuda_probe=lambda: ok, llvm_probe=lambda p: ok, candidates=lambda: ["/x"]
    )
    assert c.variant == "llvm_ad_rgb"  # 'llvm' skips CUDA even where it works
    c = choose_backend("scalar", cuda_probe=lambda: ok, llvm_probe=lambda p: ok, candidates=lambda: [])
    assert c.variant == "scalar_rgb"
    with pytest.raises(ValueError, match="render.variant"):
        choose_backend("vulkan_ad_mono", cuda_probe=lambda: ok, llvm_probe=lambda p: ok, candidates=list)
    assert variant_for("scalar", "mono") == "scalar_rgb"  # the wheel has no scalar_mono


def test_candidates_put_the_environment_first_and_newest_next(monkeypatch, tmp_path):
    fake = tmp_path / "libLLVM-99.so"
    fake.write_bytes(b"")
    monkeypatch.setenv(backend.ENV_LLVM, str(fake))
    cands = backend.llvm_candidates()
    assert cands[0] == str(fake)
    assert backend._llvm_version_key("/usr/lib/libLLVM.so.19.1") > backend._llvm_version_key("libLLVM-15.so")


def test_real_probe_of_this_machine_finds_a_working_backend():
    """On the project's machines (setup installs libllvm19) the LLVM backend passes its probe."""
    choice = choose_backend()
    assert choice.kind in ("cuda", "llvm"), choice.probes


def test_scalar_fallback_renders_the_same_rig(tmp_path):
    """The fallback variant (scalar_rgb: the wheel has no scalar_mono) runs both engines and gives
    the LLVM result within Monte Carlo noise. Run in a child: the variant is chosen per process."""
    import json
    import os

    code = (
        "import json, numpy as np\n"
        "from tests.conftest import tiny_cfg\n"
        "from bench_sim.render.exposures import render_photons\n"
        "out = {}\n"
        "for eng in ('fast', 'reference'):\n"
        "    ph, s = render_photons(tiny_cfg(), 2, np.random.default_rng(0), engine=eng)\n"
        "    out[eng] = [s.info['variant'], float(ph.mean())]\n"
        "print(json.dumps(out))\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # the repository
    res = {}
    for variant in ("scalar", "auto"):
        env = dict(os.environ, BENCH_SIM_VARIANT=variant, PYTHONPATH=root)
        proc = subprocess.run(
            [sys.executable, "-c", code], env=env, cwd=root, capture_output=True, text=True, timeout=600
        )
        assert proc.returncode == 0, proc.stderr[-2000:]
        res[variant] = json.loads(proc.stdout.strip().splitlines()[-1])
    for eng in ("fast", "reference"):
        assert res["scalar"][eng][0] == "scalar_rgb"
        assert res["auto"][eng][0] != "scalar_rgb"
        assert res["scalar"][eng][1] == pytest.approx(res["auto"][eng][1], rel=0.01)


# ---------------------------------------------------------------- a forced choice is forced
def test_forced_backends_that_cannot_run_are_one_line_errors(monkeypatch):
    from bench_sim.errors import BenchSimError

    ok, bad = ProbeResult(True, "fine"), ProbeResult(False, "no NVIDIA device found")
    probes = {"cuda_probe": lambda: bad, "llvm_probe": lambda p: ok, "candidates": lambda: ["/x"]}
    msg = r"^render.variant = 'cuda': the CUDA backend cannot run here \(no NVIDIA device found\); use 'auto'"
    with pytest.raises(BenchSimError, match=msg):
        choose_backend("cuda", **probes)
    monkeypatch.setenv("BENCH_SIM_VARIANT", "cuda_ad_mono")
    with pytest.raises(BenchSimError, match=r"^BENCH_SIM_VARIANT = 'cuda_ad_mono': the CUDA backend"):
        choose_backend(**probes)
    monkeypatch.setenv("BENCH_SIM_VARIANT", "llvm")
    probes = {"cuda_probe": lambda: ok, "llvm_probe": lambda p: bad, "candidates": lambda: ["/l/libLLVM.so"]}
    with pytest.raises(BenchSimError, match=r"'llvm': no libLLVM passed the probe \(/l/libLLVM.so: rejected"):
        choose_backend(**probes)
    # only 'auto' falls back, with a warning
    monkeypatch.setenv("BENCH_SIM_VARIANT", "auto")
    with pytest.warns(RuntimeWarning, match="scalar"):
        choice = choose_backend(cuda_probe=lambda: bad, llvm_probe=lambda p: bad, candidates=list)
    assert choice.kind == "scalar"


@pytest.mark.parametrize(
    ("name", "mode", "needle"),
    [
        ("llvm_garbage", "mono", "not a Mitsuba variant of this installation"),
        ("vulkan", "mono", "not a Mitsuba variant"),
        ("llvm_ad_spectral", "mono", "not a variant for mono rendering"),
        ("llvm_ad_mono", "spectral", "not a variant for spectral rendering"),
        ("scalar_spectral_polarized", "spectral", "not a variant for spectral"),
    ],
)
def test_unknown_or_mismatched_variant_names(name, mode, needle):
    from bench_sim.errors import BenchSimError

    with pytest.raises(BenchSimError) as info:
        backend.check_variant_name(name, mode, "render.variant")
    msg = str(info.value)
    assert msg.startswith(f"render.variant = {name!r}: {needle}") and "\n" not in msg
    assert "'auto', 'cuda', 'llvm', 'scalar'" in msg


def test_installed_variants_are_read_without_importing_mitsuba():
    code = (
        "import sys\nfrom bench_sim.runtime.backend import mitsuba_variants\n"
        "print(mitsuba_variants(), 'mitsuba' in sys.modules)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    listed, imported = proc.stdout.rsplit(" ", 1)
    assert "llvm_ad_mono" in listed and "scalar_rgb" in listed and imported.strip() == "False"


@pytest.mark.parametrize(
    "content",
    ["[1, 2]", '"text"', "{\"llvm|x\": [1]}", "{\"k\": {\"ok\": \"yes\", \"detail\": 3}}", "not json {", ""],
    ids=["list", "string", "entry list", "entry types", "not json", "empty"],
)
def test_a_probe_cache_of_the_wrong_shape_is_ignored_and_rebuilt(content):
    path = backend._cache_file()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(content)
    key = backend._cache_key("llvm", "/fake/libLLVM.so.19")
    if content.startswith("{\"k\""):  # the same shape, under the key that will be looked up
        path.write_text(content.replace('"k"', json.dumps(key)))
    calls = []

    def runner(cmd, **kwargs):
        calls.append(1)
        return subprocess.CompletedProcess(cmd, 0, "BENCH_SIM_LLVM_OK\n", "")

    assert probe_llvm("/fake/libLLVM.so.19", runner=runner).ok and calls == [1]
    data = json.loads(path.read_text())
    assert data[key] == {"ok": True, "detail": "probe kernel ran"}
    assert probe_llvm("/fake/libLLVM.so.19", runner=runner).detail.endswith("(cached)") and calls == [1]


def test_select_backend_chooses_again_when_another_kind_is_forced(monkeypatch):
    monkeypatch.setattr(backend, "_ACTIVE", None)
    monkeypatch.setattr(backend, "probe_cuda", lambda **kw: ProbeResult(False, "none"))
    first = backend.select_backend("auto")
    assert first.kind in ("llvm", "scalar")
    assert backend.select_backend("scalar").kind == "scalar"
    from bench_sim.errors import BenchSimError

    with pytest.raises(BenchSimError, match="'cuda': the CUDA backend cannot run here"):
        backend.select_backend("cuda")
