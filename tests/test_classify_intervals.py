"""Pooled block-bootstrap intervals of several test files (issue 31 C; docs/classification.md §5).

The pooled interval of ``evaluate_model`` on crop_1.laz + pont.laz was 0.64–0.96 (mean F1)
while the files' own were 0.92–0.98 and 0.92–0.94: the blocks of both files were drawn as
one pool, so a resample could hold 8 blocks of one file and 30 of the other, and the pooled
figure moved with that mix, which no test ever has.  The draw is now stratified by file.
"""
from __future__ import annotations

import numpy as np
import pytest

import lidarfx
from lidarfx.classify import ClassMap, block_bootstrap, evaluate_model

SPEC = "ground=2,vegetation=5,building=6"


class ReplayModel:
    """A stand-in for a trained model: its "prediction" of a cloud is the cloud's ``pred`` attribute."""

    def __init__(self, spec: str = SPEC) -> None:
        self.classes = ClassMap.parse(spec)
        self.min_building_area = 0.0
        self.max_multi_return_share = 1.0

    def density_check(self, cloud, name=None, warn=True):
        return None

    def predict(self, cloud, **kw):
        return np.asarray(cloud["pred"]).astype(np.int16)


def blocks_cloud(rng, nx, ny, per_block, error, codes=(2, 5), wrong=None, block=20.0):
    """A cloud of ``nx`` × ``ny`` blocks of ``block`` m, ``per_block`` points each, reference
    classes drawn from ``codes``; in block i a share ``error[i]`` of the points is predicted
    ``wrong`` (default: the other one of ``codes``)."""
    xyz, ref, pred = [], [], []
    for i in range(nx * ny):
        bx, by = i % nx, i // nx
        p = np.column_stack([rng.uniform(bx * block + 0.5, (bx + 1) * block - 0.5, per_block),
                             rng.uniform(by * block + 0.5, (by + 1) * block - 0.5, per_block),
                             rng.uniform(0, 1, per_block)])
        r = rng.choice(codes, per_block)
        bad = rng.random(per_block) < error[i]
        other = np.where(r == codes[0], codes[1], codes[0]) if wrong is None else np.full(per_block, wrong)
        xyz.append(p)
        ref.append(r)
        pred.append(np.where(bad, other, r))
    n = nx * ny * per_block
    return lidarfx.PointCloud(np.vstack(xyz), {"classification": np.concatenate(ref).astype(np.uint8),
                                                "pred": np.concatenate(pred).astype(np.uint8),
                                                "return_number": np.ones(n, np.uint8),
                                                "number_of_returns": np.ones(n, np.uint8)})


def test_pooled_interval_lies_within_the_files_intervals():
    """Two files with the same classes, one classified far better than the other (OA ≈ 0.98 and
    ≈ 0.87, a little spread between blocks): the pooled figure of the two is fixed by the files'
    sizes, so its interval lies within the hull of the files' intervals and is no wider than the
    wider of them.  Drawn as one pool (the old code) it was twice as wide as the wider file's
    (OA 0.909–0.941, width 0.031, against 0.015): a resample with more blocks of the good file
    scored higher."""
    rng = np.random.default_rng(7)
    good = blocks_cloud(rng, 6, 5, 200, rng.uniform(0.015, 0.025, 30))
    poor = blocks_cloud(rng, 6, 5, 200, rng.uniform(0.12, 0.14, 30))
    sec = evaluate_model(ReplayModel(), [good, poor], bootstrap=2000)
    per = [m["ci"] for m in sec["files"].values()]
    pooled = sec["metrics"]["ci"]
    assert pooled["strata"] == 2 and "stratified" in pooled["method"]
    for key in ("oa", "mean_f1", "kappa"):
        lo, hi = min(c[key][0] for c in per), max(c[key][1] for c in per)
        widest = max(c[key][1] - c[key][0] for c in per)
        assert lo - 0.005 <= pooled[key][0] < sec["metrics"][key] < pooled[key][1] <= hi + 0.005, (key, pooled, per)
        assert pooled[key][1] - pooled[key][0] <= widest * 1.05, (key, pooled[key], widest)


def test_pooled_interval_keeps_every_file_in_its_share():
    """Every block of a file alike (no spread inside a file): a file's interval is a single
    value, and so is the pooled one when each resample holds each file's blocks in their own
    number.  Drawn as one pool, the pooled OA ran between the two files' values."""
    ref = np.tile([0, 1], 2000)  # 40 blocks of 100 points
    blocks = np.repeat(np.arange(40), 100)
    files = (blocks >= 20).astype(np.int64)  # blocks 0-19: file 0, 20-39: file 1
    pred = ref.copy()
    pred[(files == 1) & (np.arange(len(ref)) % 10 == 0)] = 1  # file 1: every tenth point called class 1
    ci = block_bootstrap(ref, pred, blocks, 2, strata=files)
    expected = float((ref == pred).mean())
    assert ci["oa"] == pytest.approx([expected, expected])
    assert ci["strata"] == 2 and ci["blocks"] == 40
    wide = block_bootstrap(ref, pred, blocks, 2)  # one pool: the mix of files varies
    assert wide["oa"][1] - wide["oa"][0] > 0.01
    # one stratum draws exactly as the unstratified bootstrap (the files' own intervals do not move)
    assert block_bootstrap(ref, pred, blocks, 2, strata=np.zeros(len(ref), np.int64), seed=3) == \
        block_bootstrap(ref, pred, blocks, 2, seed=3)


def test_pooled_interval_names_a_class_that_one_file_lacks():
    """crop_1 + pont in small: the building class has reference points in few blocks of one file
    only, and the other file has false buildings.  The pooled building F1 then depends on how many
    of those blocks a resample holds, so the pooled interval may reach below the files' own: the
    report says why, and the pooled interval is no wider than the draw of files' blocks explains."""
    rng = np.random.default_rng(3)
    a = blocks_cloud(rng, 5, 3, 200, np.full(15, 0.02))
    cls = np.asarray(a["classification"]).copy()
    pred = np.asarray(a["pred"]).copy()
    blk = (np.floor(a.xyz[:, 0] / 20) + 5 * np.floor(a.xyz[:, 1] / 20)).astype(int)
    house = np.isin(blk, [5, 9, 10]) & (rng.random(len(cls)) < 0.5)
    cls[house] = 6
    pred[house] = 6
    a["classification"], a["pred"] = cls, pred
    b = blocks_cloud(rng, 6, 4, 200, np.where(np.arange(24) % 3 == 0, 0.05, 0.0), wrong=6)
    sec = evaluate_model(ReplayModel(), [a, b], bootstrap=1000)
    pooled = sec["metrics"]["ci"]
    assert pooled["strata"] == 2
    notes = " ".join(sec["metrics"].get("interval_notes", []))
    assert "building" in notes and "3 of 39 blocks" in notes, pooled
    from lidarfx.classify.report import format_metrics

    assert "building" in format_metrics(sec["metrics"])
