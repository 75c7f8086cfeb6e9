"""``./run bench``: the batch command finds the checkout's benchmarks (bench/bench_<name>.py)."""
import os
import subprocess
import sys

from ...conftest import REPO


def test_bench_list_names_the_benchmarks_of_the_checkout():
    res = subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "bench", "list"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    expected = sorted(n[len("bench_"):-3] for n in os.listdir(os.path.join(REPO, "bench"))
                      if n.startswith("bench_") and n.endswith(".py"))
    assert expected and all(name in res.stdout for name in expected), res.stdout
