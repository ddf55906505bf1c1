"""The ``--report OUTDIR`` option of the analysis commands: the run as one HTML page.

Every analysis command builds the same page (:class:`lidarfx.report.Report`): its
summary (the ``--json`` summary) as tables, its output files as links, its pictures
embedded, its cloud in the 3-D viewer and its vector products (wires, edges,
breaklines, members) drawn over the cloud.  The folder is checked before any work;
the page is written last, atomically.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

REPORT_HELP = ("also write an HTML report to this folder (OUTDIR/index.html): the cloud in a 3-D viewer with the "
               "products drawn in, the pictures and tables; docs/report.md")
MAX_REPORT_POINTS = 1_000_000


def add_report_option(p) -> None:
    """The ``--report OUTDIR`` option."""
    p.add_argument("--report", default=None, metavar="OUTDIR", help=REPORT_HELP)


def command_line(args) -> str:
    """The command as the user typed it (for the page's header)."""
    return getattr(args, "command_line", None) or "lidarfx"


class ReportJob:
    """The report of one command run: checked at the start, written at the end.

    ``picture(name)`` gives a temporary PNG path for a picture the command draws only
    for the report; :meth:`write` embeds it, writes ``OUTDIR/index.html`` and removes the
    temporary files.  Without ``--report`` every method is a no-op (``wanted`` is False).
    """

    def __init__(self, args) -> None:
        from ._args import check_output_dir

        folder = getattr(args, "report", None)
        self.dir = check_output_dir(folder, files=("index.html",)) if folder else None  # the page is its one file
        self.command = command_line(args)
        self._tmp: str | None = None

    @property
    def wanted(self) -> bool:
        return self.dir is not None

    def scratch(self) -> Path:
        """A temporary folder for pictures drawn for the report only (removed by :meth:`write`)."""
        if self._tmp is None:
            self._tmp = tempfile.mkdtemp(prefix="lidarfx-report-")
        return Path(self._tmp)

    def picture(self, name: str) -> Path:
        """A temporary path for a picture drawn for the report only."""
        return self.scratch() / name

    def sample(self, n: int):
        """Indices (sorted) of the points a report of ``n`` points shows: all, or a seeded
        random subsample of :data:`MAX_REPORT_POINTS`."""
        import numpy as np

        if n <= MAX_REPORT_POINTS:
            return np.arange(n)
        return np.sort(np.random.default_rng(0).choice(n, MAX_REPORT_POINTS, replace=False))

    def write(self, title: str, summary: Mapping[str, Any], *, cloud=None, attributes: Sequence[str] | None = None,
              labels: Mapping[str, Mapping[int, str]] | None = None, colour_by: str | None = None,
              lines: Mapping[str, Sequence] | None = None, pictures: Iterable[tuple[str | Path, str]] = (),
              points: int | None = None) -> str | None:
        """Write the page; returns its path (None without ``--report``).

        ``summary`` is the command's JSON summary: its numbers and texts become the key
        figures, its lists of records and its mappings tables, its ``outputs`` links (PNG
        outputs are embedded).  ``lines`` maps a layer name to
        :class:`lidarfx.vector.Polyline` objects or ``(k, 3)`` arrays; ``pictures`` are
        ``(path, caption)`` pairs; ``points`` the size of the whole cloud when ``cloud`` is
        a subsample of it."""
        if self.dir is None:
            return None
        from ..report import Report
        from ..report.sections import (known_labels, line_layer, output_files, output_pictures, product_first,
                                       summary_sections)

        try:
            rep = Report(title, command=self.command, max_points=MAX_REPORT_POINTS)
            figures, tables = summary_sections(summary)
            if points is not None:
                figures = {"points": points, **{k: v for k, v in figures.items() if k != "points"}}
            rep.add_summary(figures)
            if cloud is not None and len(cloud):
                if colour_by is not None and colour_by not in cloud:
                    colour_by = None
                rep.add_cloud(cloud, attributes or product_first(cloud, colour_by),
                              labels={**known_labels(cloud), **(labels or {})}, colour_by=colour_by)
            for name, layer in (lines or {}).items():
                arrays, props = line_layer(layer)
                if arrays:
                    rep.add_lines(name, arrays, properties=props)
            shown = set()
            for path, caption in [*pictures, *output_pictures(summary)]:
                key = os.path.realpath(path)
                if key not in shown and Path(path).is_file():
                    shown.add(key)
                    rep.add_picture(path, caption)
            for name, rows in tables:
                rep.add_table(name, rows)
            for name, path in output_files(summary):
                rep.add_link(name, os.path.relpath(os.path.abspath(path), os.path.abspath(self.dir)), str(path))
            page = rep.write(self.dir)
        finally:
            if self._tmp is not None:
                shutil.rmtree(self._tmp, ignore_errors=True)
                self._tmp = None
        return str(page)
