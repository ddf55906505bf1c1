"""The layout of lidarfx.classify after the split of evaluate.py (issue 31 A).

evaluate.py held metrics, folds, reports and pictures and imported importance.py, which
imported evaluate.py back inside a function.  Now metrics.py, folds.py and report.py hold
their parts, the pictures are in lidarfx.render.classify_plots, importance.py imports
folds.py and metrics.py at its top, and every name is still importable from evaluate.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import lidarfx.classify

CLASSIFY = Path(lidarfx.classify.__file__).parent


def _imports(path: Path) -> list[tuple[ast.ImportFrom, bool]]:
    """``(node, at_top)`` for every ``from … import …`` of a module (at_top: not inside a function)."""
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    return [(n, id(n) in top) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]


def test_importance_and_evaluate_import_each_other_one_way_at_the_top():
    imp = _imports(CLASSIFY / "importance.py")
    assert not [n for n, _ in imp if n.level == 1 and n.module == "evaluate"], "importance imports evaluate"
    ev = _imports(CLASSIFY / "evaluate.py")
    assert [top for n, top in ev if n.level == 1 and n.module == "importance"] == [True]
    # every module of the package imports its siblings at the top (no import inside a function to break a circle)
    for path in sorted(CLASSIFY.glob("*.py")):
        inner = [n.module for n, top in _imports(path) if n.level == 1 and not top
                 and n.module in ("evaluate", "importance", "metrics", "folds", "report")]
        assert not inner, (path.name, inner)


@pytest.mark.parametrize("module", ["importance", "metrics", "folds", "report"])
def test_each_module_imports_alone(module):
    out = subprocess.run([sys.executable, "-c", f"import lidarfx.classify.{module}"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_classify_plots_do_not_need_the_classify_package():
    code = ("import sys, lidarfx.render.classify_plots as p; "
            "assert 'lidarfx.classify' not in sys.modules, 'imports lidarfx.classify'; print(p.__all__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_no_private_name_crosses_a_module_of_the_package():
    for path in sorted(CLASSIFY.glob("*.py")):
        for node, _ in _imports(path):
            if node.level == 1 and node.module:  # from .sibling import …
                private = [a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
                assert not private, (path.name, node.module, private)


def test_every_name_is_importable_where_it_was():
    E = sys.modules["lidarfx.classify.evaluate"]  # the package's `evaluate` is the function
    names = ["LAYOUT", "confusion_matrix", "metrics", "random_folds", "block_folds", "block_ids", "block_bootstrap",
             "block_buffer_mask", "file_buffer_mask", "cross_validate", "evaluate", "evaluate_model", "format_metrics",
             "format_report", "write_report", "plot_confusion", "plot_importance", "plot_elimination",
             "terrain_slope", "SLOPE_BINS", "slope_confusions", "HeldOutRule", "report_json", "fold_parts",
             "default_buffer", "format_slope_table", "MIN_BLOCK_SIZE", "MAX_BOOTSTRAP",
             # the private names tests and benchmarks import from here
             "_labelled", "_file_features", "_thinned_features", "_small_buildings_line", "_metrics_for", "_out_dir"]
    for name in names:
        assert hasattr(E, name), name
    for name in lidarfx.classify.__all__:
        assert hasattr(lidarfx.classify, name), name
    from lidarfx.classify.folds import block_folds
    from lidarfx.classify.metrics import block_bootstrap
    from lidarfx.classify.report import format_metrics
    from lidarfx.render.classify_plots import plot_confusion

    assert E.block_folds is block_folds and E.block_bootstrap is block_bootstrap
    assert E.format_metrics is format_metrics and E.plot_confusion is plot_confusion
    assert lidarfx.classify.plot_confusion is plot_confusion


def test_evaluate_checks_the_folds_before_the_features(monkeypatch):
    """As tests/test_classify.py checks through the old private name, with the public one."""
    import lidarfx
    from lidarfx.classify import evaluate
    from lidarfx.errors import LidarfxError

    E = sys.modules["lidarfx.classify.evaluate"]

    def no_features(*a, **k):
        raise AssertionError("features computed before the fold check")

    monkeypatch.setattr(E, "file_features", no_features)
    cloud = lidarfx.synth.facade(seed=1, density=60.0)
    with pytest.raises(LidarfxError, match="spatial block"):
        evaluate([cloud], classes="ground=2,wall=6", cv=5, block_size=1000.0, features="eigen", radii=[0.5])
