"""The developer tools in tools/ still start from their place outside the package."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parents[1]
REPO = TOOLS.parent


@pytest.mark.parametrize("tool", ["kernel_ab", "stage_ab", "kernel_loops"])
def test_each_tool_runs_as_a_script_from_the_repository_root(tool):
    done = subprocess.run([sys.executable, f"tools/{tool}.py", "--help"], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"usage: {tool}.py")


def test_each_tool_is_out_of_the_installed_packages():
    for tool in ("kernel_ab", "stage_ab", "kernel_loops"):
        assert not (REPO / "host" / "eelhost" / "benchmarks" / f"{tool}.py").exists()
        assert importlib.util.find_spec(f"eelhost.benchmarks.{tool}") is None


def test_kernel_ab_exports_a_revisions_twin_from_this_repository(tmp_path):
    spec = importlib.util.spec_from_file_location("kernel_ab", TOOLS / "kernel_ab.py")
    kernel_ab = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(kernel_ab)
    folder = kernel_ab.export_revision("HEAD", tmp_path)
    exported = (folder / "eelsim" / "__init__.py").read_bytes()
    at_head = subprocess.run(["git", "show", "HEAD:sim/eelsim/__init__.py"], cwd=REPO,
                             capture_output=True, check=True).stdout
    assert exported == at_head
    # the working tree's side of the comparison is this clone's sim/ folder
    assert (kernel_ab._REPO / "sim" / "eelsim" / "__init__.py").is_file()
