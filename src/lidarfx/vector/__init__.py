"""The vector layer: 3-D polylines (edges, wires, breaklines, members), robust line fits and writers.

The one place the products (edges, power lines, breaklines, tower members) fit,
merge, chain, simplify and export lines: :mod:`.lines` (least-squares and
RANSAC lines, segments from point bands, collinear merging, chaining, 3-D
Douglas–Peucker), :mod:`.polyline` (the :class:`Polyline` record) and
:mod:`.export` (GeoJSON, DXF, CSV, JSON).
"""
from .export import (
    crs_name,
    export_lines,
    read_geojson,
    write_csv,
    write_dxf,
    write_geojson,
    write_json,
    write_vertices_csv,
)
from .lines import (
    LineSegment,
    chain_segments,
    closest_points_of_lines,
    douglas_peucker,
    extract_segments,
    fit_line,
    merge_collinear,
    point_line_distance,
    point_polyline_distance,
    ransac_line,
)
from .polyline import Polyline

__all__ = [
    "Polyline",
    "LineSegment",
    "fit_line",
    "ransac_line",
    "extract_segments",
    "merge_collinear",
    "chain_segments",
    "douglas_peucker",
    "point_line_distance",
    "point_polyline_distance",
    "closest_points_of_lines",
    "crs_name",
    "export_lines",
    "read_geojson",
    "write_csv",
    "write_dxf",
    "write_geojson",
    "write_json",
    "write_vertices_csv",
]
