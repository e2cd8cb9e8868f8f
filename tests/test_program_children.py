"""Child processes of a ``bench-sim`` run start alike whether it runs as the console script or as
``python -m bench_sim``: multiprocessing's ``spawn`` (Dask's workers) never runs the program
module in them (``bench_sim.__main__._children_skip_the_script``)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

#: a program like the ``bench-sim`` console script (which imports ``main`` from the program
#: module), spawning one child that reports which of the program's modules it holds
SCRIPT = """
import multiprocessing as mp, sys
from bench_sim.__main__ import _children_skip_the_script, main
from bench_sim_child_probe import child
if __name__ == "__main__":
    if sys.argv[1] == "as-main-does":
        _children_skip_the_script()
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=child, args=(q,))
    p.start()
    print(",".join(q.get()))
    p.join()
"""
PROBE = """
import sys
def child(q):
    q.put(sorted(m for m in ("bench_sim.cli", "bench_sim.__main__") if m in sys.modules))
"""


@pytest.mark.parametrize(("how", "held"), [
    ("as-main-does", ""), ("without", "bench_sim.__main__,bench_sim.cli"),
])
def test_a_console_scripts_spawned_child_skips_the_program_module(tmp_path, how: str, held: str) -> None:
    """Without the step ``main`` takes first, the child ran the script again and so imported the
    whole command line and made itself bench-sim's own (its signal handlers); with it, nothing."""
    (tmp_path / "script.py").write_text(SCRIPT)
    (tmp_path / "bench_sim_child_probe.py").write_text(PROBE)
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    done = subprocess.run([sys.executable, "script.py", how], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == held
