"""A pipeline's cloud steps fused into one chunk task (``lidarfx run --chunk-size``,
docs/pipelines.md "In chunks").

The options hold the steps in order, each with its command's chunk options and its ``reach``
(the buffer its neighbourhoods need, coordinate units).  A chunk reads its square with the sum
of the reaches around it; step *k* computes the points within the reaches of the steps after
it (step *k + 1* needs step *k*'s results on its neighbours), over everything the steps before
left; the last step computes the chunk's own square only.  Each step runs the processor its
command runs in chunks, so every point's values are those of the commands' chunked runs one
after the other, without files in between.

A buffer narrower than the sum (``--buffer``) is taken from the first steps: the last steps keep
their whole reach as long as the buffer holds it.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import LidarfxError
from .processors import Processor, get


def _steps(o: dict) -> list[dict]:
    steps = o.get("steps")
    if not isinstance(steps, list) or not steps:
        raise LidarfxError("pipeline options need 'steps' (use lidarfx.pipeline.chunked)")
    return steps


def pipeline_buffer(o: dict, density: float) -> tuple[float, bool]:
    """The sum of the steps' reaches; exact when every step's is."""
    steps = _steps(o)
    return float(sum(float(s["reach"]) for s in steps)), all(bool(s["exact"]) for s in steps)


def check_pipeline_options(o: dict) -> None:
    for s in _steps(o):
        if s.get("command") == "pipeline":
            raise LidarfxError("a pipeline step cannot be a pipeline")
        r = s.get("reach")
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not (math.isfinite(r) and r >= 0):
            raise LidarfxError(f"step reach must be a number >= 0, got {r!r}")
        get(s["command"]).check(s["options"])


def _within(xy: np.ndarray, square: tuple[float, float, float, float], grow: float) -> np.ndarray:
    """Points within ``grow`` of the square (a box test, widened by a relative 1e-9 so that
    rounding never drops a point at the edge)."""
    x0, y0, x1, y1 = square
    g = grow * (1.0 + 1e-9) + 1e-9 * max(1.0, x1 - x0)
    return (xy[:, 0] >= x0 - g) & (xy[:, 0] <= x1 + g) & (xy[:, 1] >= y0 - g) & (xy[:, 1] <= y1 + g)


def pipeline_process(chunk, ctx, o: dict):
    """The chunk's own points after every step; ``(points, kept)`` when a step drops points.
    ``meta["chunk_info"]`` carries per step the number of the square's points after it (and the
    ground points of ``ground``, the classes of ``classify``)."""
    from .engine import Chunk, Context
    from .plan import Grid

    steps = _steps(o)
    total = float(ctx.grid.buffer)
    reaches = [float(s["reach"]) for s in steps]
    # grow[k]: how far around the square step k computes = what the steps after it reach (capped)
    grow = [min(total, sum(reaches[k + 1:])) for k in range(len(steps))]
    i, j = chunk.cell
    square = chunk.square(ctx)
    cloud, pos = chunk.cloud, np.arange(len(chunk.cloud))
    ids, source = chunk.ids, chunk.source
    dropped = False
    counts = []
    for k, s in enumerate(steps):
        xy = cloud.xyz[:, :2]
        ci, cj = ctx.grid.cells(xy[:, 0], xy[:, 1])
        in_square = (ci == int(i)) & (cj == int(j))
        own = in_square | _within(xy, square, grow[k]) if grow[k] > 0 else in_square
        if not in_square.any():  # nothing of the square is left (a crop, a select): the chunk writes nothing
            counts += [{"points": 0} for _ in steps[k:]]
            cloud, pos, dropped = cloud.subset(in_square), pos[in_square], True
            break
        reach_now = min(total, grow[k] + reaches[k])
        sub_ctx = Context(ctx.mins, ctx.maxs, ctx.points, Grid(ctx.grid.size, reach_now), ctx.threads)
        result = get(s["command"]).process(Chunk(chunk.name, cloud, own, ids, source, (int(i), int(j))), sub_ctx,
                                           s["options"])
        keep = np.ones(int(own.sum()), dtype=bool)
        if isinstance(result, tuple):
            result, keep = result
            keep = np.asarray(keep, dtype=bool)
            dropped = True
        result.meta.pop("chunk_info", None)
        pos, ids, source = pos[own][keep], ids[own][keep], source[own][keep]
        mine = in_square[own][keep]  # the square's points after the step (counted once over all chunks)
        row = {"points": int(mine.sum())}
        if s["command"] == "ground" and "classification" in result:
            row["ground_points"] = int(np.count_nonzero(np.asarray(result["classification"])[mine] == 2))
        if s["command"] == "classify" and "classification" in result:
            c, n = np.unique(np.asarray(result["classification"])[mine], return_counts=True)
            row["classes"] = {str(int(a)): int(b) for a, b in zip(c, n)}
        counts.append(row)
        cloud = result
    # the last step computed the square only (grow = 0): these are the chunk's own points
    result = cloud
    result.meta["chunk_info"] = {"steps": counts}
    if not dropped:
        return result
    kept = np.isin(np.flatnonzero(chunk.own), pos)
    return result, kept


PROCESSORS = {"pipeline": Processor(pipeline_buffer, pipeline_process, check_pipeline_options, identical=False)}
