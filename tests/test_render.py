"""Pictures: the rasters behind the PNGs are checked cell by cell."""
import numpy as np

from lidarfx.render import (
    CLASS_COLOURS,
    NOT_CLASSIFIED,
    _raster_cells,
    class_map,
    class_raster,
    error_images,
    error_map,
)


def _grid(n=20, offset=(500_000.0, 6_000_000.0)):
    """One point per 1 m cell centre on an n x n m square far from the origin."""
    g = np.arange(n) + 0.5
    x, y = np.meshgrid(g, g)
    xy = np.c_[x.ravel() + offset[0], y.ravel() + offset[1]]
    return xy, np.zeros(len(xy))


def test_raster_cells_start_at_the_data_not_at_zero():
    xy, _ = _grid(10)
    cell, nu, nv, pix = _raster_cells(xy[:, 0], xy[:, 1], pixels=100, cell=1.0)
    assert (cell, nu, nv) == (1.0, 10, 10)
    assert np.array_equal(np.sort(pix), np.arange(100))  # every cell once: nothing clipped to the edge


def test_error_images_put_each_error_in_its_cell():
    xy, z = _grid(20)
    ix = np.round(xy[:, 0] - xy[:, 0].min()).astype(int)  # = raster column (1 m cells from the data)
    iy = np.round(xy[:, 1] - xy[:, 1].min()).astype(int)  # = raster row, south first
    ref = (ix >= 10).astype(np.int64)  # ground west, building east
    pred = ref.copy()
    square = (ix >= 12) & (ix < 16) & (iy >= 2) & (iy < 6)  # 16 building cells called ground
    pred[square] = 0
    strip = (ix < 2) & (iy >= 15)  # 10 ground cells called building
    pred[strip] = 1
    ref[(ix >= 18) & (iy >= 18)] = -1  # 4 points not scored: never an error
    im = error_images(xy, z, ref, pred, ["ground", "building"], cell=1.0)
    assert im["left"].shape == (20, 20, 3) and im["cell"] == 1.0
    assert im["pairs"] == {"building → ground": 16, "ground → building": 10}
    assert im["wrong"] == 26 and im["scored"] == 396 and im["other"] == 0
    right = im["right"]
    col = dict(zip(im["pairs"], im["pair_colours"]))
    assert np.allclose(right[2:6, 12:16], col["building → ground"])  # one point per cell: share 1 -> full colour
    assert np.allclose(right[15:20, 0:2], col["ground → building"])
    untouched = np.ones((20, 20), bool)
    untouched[2:6, 12:16] = untouched[15:20, 0:2] = False
    grey = right[untouched]
    assert np.allclose(grey[:, 0], grey[:, 1]) and np.allclose(grey[:, 1], grey[:, 2])  # no error: grey
    # left panel: the predicted class of each cell
    assert np.allclose(im["left"][3, 13], _rgb(CLASS_COLOURS["ground"]))  # the mistaken square
    assert np.allclose(im["left"][3, 5], _rgb(CLASS_COLOURS["ground"]))
    assert np.allclose(im["left"][10, 15], _rgb(CLASS_COLOURS["building"]))
    assert np.allclose(im["left"][17, 1], _rgb(CLASS_COLOURS["building"]))


def _rgb(c):
    from matplotlib.colors import to_rgb

    return np.array(to_rgb(c))


def test_error_images_dominant_pair_and_pale_cells():
    # one 2 m cell with 10 points: 3 wrong as a -> b, 1 wrong as a -> c, 6 right
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 1.9, (10, 2))
    xy = np.vstack([xy, [[10.0, 10.0]]])  # a far point so the raster has more than one cell
    ref = np.zeros(11, np.int64)
    pred = np.array([1, 1, 1, 2, 0, 0, 0, 0, 0, 0, 0])
    im = error_images(xy, np.zeros(11), ref, pred, ["a", "b", "c"], cell=2.0, max_pairs=1)
    assert im["pairs"] == {"a → b": 3} and im["other"] == 1
    share = 4 / 10
    alpha = 0.35 + 0.65 * min(1.0, share / 0.5)
    expect = (1 - alpha) + alpha * im["pair_colours"][0]
    assert np.allclose(im["right"][0, 0], expect)


def test_error_map_writes_a_png(tmp_path):
    xy, z = _grid(10)
    ref = np.zeros(len(xy), np.int64)
    path, pairs = error_map(xy, z, ref, ref, ["ground"], tmp_path / "e.png", title="t")
    assert path.is_file() and path.stat().st_size > 1000 and pairs == {}
    assert not list(tmp_path.glob(".*part*"))  # no temporary file left


def test_class_raster_shows_the_highest_point_and_unclassified_grey(tmp_path):
    xy, _ = _grid(4)
    xy = np.vstack([xy, xy[:1]])  # a second point in cell (0, 0), higher, of class 1
    z = np.r_[np.zeros(16), 5.0]
    cls = np.r_[np.zeros(16, np.int64), 1]
    cls[5] = -1  # cell (row 1, col 1) not classified
    cr = class_raster(xy, z, cls, ["ground", "building"], cell=1.0)
    assert cr["image"].shape == (4, 4, 3)
    assert np.allclose(cr["image"][0, 0], _rgb(CLASS_COLOURS["building"]))  # the higher point wins
    assert np.allclose(cr["image"][1, 1], NOT_CLASSIFIED)
    assert np.allclose(cr["image"][3, 3], _rgb(CLASS_COLOURS["ground"]))
    assert class_map(xy, z, cls, ["ground", "building"], tmp_path / "c.png").is_file()

