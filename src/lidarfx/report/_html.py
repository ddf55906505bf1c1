"""HTML pieces of the report page: value formatting, tables, the style sheet."""
from __future__ import annotations

import html
import math
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

TABLE_ROWS_MAX = 1000
"""Rows of one HTML table at most (the rest is counted in a note)."""


def esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


def fmt(value: Any) -> str:
    """A table cell's text: integers as they are, floats to 6 significant digits (at least
    2 decimals from 1 to 10 million, so coordinates keep centimetres) without exponent
    between 1e-4 and 1e12 and without trailing zeros; NaN / ±inf / None empty."""
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if not math.isfinite(v):
            return ""
        a = abs(v)
        if a == 0:
            return "0"
        if a < 1e-4 or a >= 1e12:
            return f"{v:.4g}"
        digits = math.floor(math.log10(a)) + 1
        decimals = max(0, 6 - digits)
        if 1 <= a < 1e7:
            decimals = max(decimals, 2)
        text = f"{v:.{decimals}f}"
        return text.rstrip("0").rstrip(".") if "." in text else text
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return ", ".join(fmt(v) for v in value)
    return str(value)


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def columns_of(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """The union of the rows' keys, in order of first appearance."""
    cols: dict[str, None] = {}
    for r in rows:
        for k in r:
            cols.setdefault(str(k), None)
    return list(cols)


def table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None, *, css: str = "data",
          limit: int = TABLE_ROWS_MAX) -> str:
    """An HTML table of dict rows (missing cells empty; numbers right-aligned)."""
    rows = list(rows)
    cols = list(columns) if columns is not None else columns_of(rows)
    out = [f'<div class="table-wrap"><table class="{css}"><thead><tr>']
    out += [f"<th>{esc(c)}</th>" for c in cols]
    out.append("</tr></thead><tbody>")
    for r in rows[:limit]:
        cells = {str(k): v for k, v in r.items()}
        out.append("<tr>")
        for c in cols:
            v = cells.get(c)
            cls = ' class="num"' if is_number(v) else ""
            out.append(f"<td{cls}>{esc(fmt(v))}</td>")
        out.append("</tr>")
    out.append("</tbody></table></div>")
    if len(rows) > limit:
        out.append(f'<p class="note">First {limit:,} of {len(rows):,} rows shown.</p>')
    return "".join(out)


def key_values(items: Mapping[str, Any], css: str = "kv") -> str:
    """A two-column table: name, value."""
    out = [f'<table class="{css}"><tbody>']
    for k, v in items.items():
        cls = ' class="num"' if is_number(v) else ""
        out.append(f"<tr><th>{esc(k)}</th><td{cls}>{esc(fmt(v))}</td></tr>")
    out.append("</tbody></table>")
    return "".join(out)


CSS = """
:root { --fg: #1d2127; --muted: #5d6672; --line: #dde1e6; --bg: #ffffff; --band: #f5f7f9; --accent: #1f6feb; }
* { box-sizing: border-box; }
body { margin: 0; color: var(--fg); background: var(--bg);
  font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
main { max-width: 1280px; margin: 0 auto; padding: 24px 28px 48px; }
h1 { font-size: 1.6rem; margin: 0 0 .4rem; }
h2 { font-size: 1.15rem; margin: 2rem 0 .6rem; padding-bottom: .25rem; border-bottom: 1px solid var(--line); }
h3 { font-size: 1rem; margin: 1.2rem 0 .4rem; }
code, pre { font: 13px/1.45 ui-monospace, SFMono-Regular, Menlo, Consolas, "Liberation Mono", monospace; }
pre.command { background: var(--band); border: 1px solid var(--line); border-radius: 6px; padding: 8px 12px;
  overflow-x: auto; white-space: pre-wrap; word-break: break-all; margin: .4rem 0 1rem; }
.note { color: var(--muted); font-size: .9rem; margin: .3rem 0; }
a { color: var(--accent); }
.table-wrap { overflow-x: auto; max-height: 520px; overflow-y: auto; border: 1px solid var(--line); border-radius: 6px; }
table { border-collapse: collapse; font-size: .88rem; }
table.data { width: 100%; }
table.data th, table.data td { padding: 4px 10px; border-bottom: 1px solid var(--line); text-align: left; white-space: nowrap; }
table.data thead th { position: sticky; top: 0; background: var(--band); font-weight: 600; }
table.data tbody tr:nth-child(even) { background: #fafbfc; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
table.kv th { text-align: left; font-weight: 600; padding: 3px 18px 3px 0; vertical-align: top; white-space: nowrap; }
table.kv td { padding: 3px 0; }
table.kv td.num { text-align: left; }
figure { margin: 1rem 0 1.6rem; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--line); border-radius: 6px; }
figcaption { color: var(--muted); font-size: .9rem; margin-top: .3rem; }
ul.links { padding-left: 1.2rem; }
ul.links li { margin: .25rem 0; }
footer { color: var(--muted); font-size: .8rem; margin-top: 3rem; border-top: 1px solid var(--line); padding-top: .6rem; }
/* viewer */
.lfx-viewer { border: 1px solid var(--line); border-radius: 8px; overflow: hidden; background: #16181d; }
.lfx-toolbar { display: flex; flex-wrap: wrap; gap: 6px 18px; align-items: center; padding: 8px 12px;
  background: var(--band); border-bottom: 1px solid var(--line); font-size: .88rem; }
.lfx-toolbar select, .lfx-toolbar button { font: inherit; padding: 2px 6px; }
.lfx-toolbar input[type=range] { vertical-align: middle; width: 110px; }
.lfx-layers { display: inline-flex; flex-wrap: wrap; gap: 4px 14px; }
.lfx-layer { white-space: nowrap; }
.lfx-stage { position: relative; height: min(72vh, 760px); min-height: 360px; }
.lfx-canvas { display: block; touch-action: none; cursor: crosshair; }
.lfx-swatch { display: inline-block; width: 11px; height: 11px; border-radius: 2px; vertical-align: -1px;
  border: 1px solid rgba(0,0,0,.25); }
.lfx-legend, .lfx-pick { position: absolute; background: rgba(255,255,255,.94); color: var(--fg);
  border-radius: 6px; font-size: .8rem; box-shadow: 0 1px 4px rgba(0,0,0,.35); }
.lfx-legend { left: 10px; bottom: 10px; padding: 6px 9px; max-height: 55%; overflow-y: auto; min-width: 150px; }
.lfx-legend-title, .lfx-pick-title { font-weight: 600; margin-bottom: 3px; }
.lfx-legend-row { white-space: nowrap; }
.lfx-count { color: var(--muted); float: right; margin-left: 10px; font-variant-numeric: tabular-nums; }
.lfx-bar { width: 180px; height: 10px; border-radius: 2px; }
.lfx-bar-labels { display: flex; justify-content: space-between; font-variant-numeric: tabular-nums; }
.lfx-pick { right: 10px; top: 10px; padding: 8px 10px; max-height: calc(100% - 20px); overflow-y: auto; min-width: 190px; }
.lfx-pick[hidden] { display: none; }
.lfx-pick-table th { text-align: left; padding: 1px 12px 1px 0; font-weight: 500; color: var(--muted); }
.lfx-pick-table td { text-align: right; font-variant-numeric: tabular-nums; }
.lfx-close { float: right; border: 0; background: none; font-size: 1.1rem; line-height: 1; cursor: pointer; margin-left: 8px; }
.lfx-help { position: absolute; right: 10px; bottom: 8px; color: #c9ced6; font-size: .75rem; pointer-events: none; }
.lfx-nowebgl { padding: 24px; color: #f0f2f4; }
"""
