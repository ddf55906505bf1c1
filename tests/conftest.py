"""Shared test helpers."""
from __future__ import annotations

import pytest


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
