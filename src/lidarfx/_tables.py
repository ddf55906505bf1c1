"""Tables a GIS or spreadsheet user opens: CSV rows and JSON documents, written atomically."""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

from ._atomic import atomic_path


def _cell(v: Any) -> Any:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return v


def write_csv_rows(path: str | Path, rows: Iterable[dict[str, Any]], columns: Sequence[str] | None = None) -> Path:
    """One CSV row per record; the header is ``columns`` or every key in first-seen order.
    ``None`` and non-finite floats become empty fields."""
    rows = list(rows)
    cols: list[str] = list(columns) if columns is not None else []
    if columns is None:
        for r in rows:
            for k in r:
                if k not in cols:
                    cols.append(k)
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: _cell(r.get(k)) for k in cols})
    return Path(path)


def write_json_doc(path: str | Path, doc: Any, *, indent: int = 1) -> Path:
    """``doc`` as JSON (NaN and inf as null, numpy values as numbers), atomically."""
    from ._json import dump

    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        dump(doc, fh, indent=indent)
        fh.write("\n")
    return Path(path)
