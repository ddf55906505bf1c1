"""Shared test helpers."""
from __future__ import annotations

import os

import pytest

# the one-line "compiling kernels" notice of a cold numba cache would add a line to the stderr that
# tests compare; tests/test_numba_cache.py checks the notice itself
os.environ.setdefault("LIDARFX_COMPILE_NOTICE", "0")


@pytest.fixture
def run_cli(capsys):
    """Run ``lidarfx`` in-process: ``run_cli([...])`` → ``(exit code, stdout, stderr)``."""
    from lidarfx.cli import main

    def run(argv):
        try:
            rc = main(list(argv))
        except SystemExit as exc:
            rc = exc.code
        out = capsys.readouterr()
        return rc, out.out, out.err

    return run
