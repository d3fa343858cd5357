"""The ``yarnfit`` console script exists from day one."""

import subprocess
import sys
from pathlib import Path

import yarnfit


def run(*args: str) -> subprocess.CompletedProcess:
    # The script installed next to this interpreter by `pip install -e .`.
    script = Path(sys.executable).parent / "yarnfit"
    return subprocess.run([str(script), *args], capture_output=True, text=True, timeout=120)


def test_version():
    out = run("--version")
    assert out.returncode == 0
    assert out.stdout.strip() == f"yarnfit {yarnfit.__version__}"


def test_help():
    out = run("--help")
    assert out.returncode == 0
    assert "usage: yarnfit" in out.stdout
    assert "fabric" in out.stdout
