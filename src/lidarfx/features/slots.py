"""Feature slots: the one table mapping feature names to kernel slots and groups.

Kernels write a feature only when ``col[slot] >= 0``; the registry
(:mod:`lidarfx.features.registry`) turns a user's ``--features`` list into
that column map.  Slot numbers are compile-time constants for numba.
"""
from __future__ import annotations

import numba as nb

# fmt: off
EIGENVALUE1, EIGENVALUE2, EIGENVALUE3, EIGENVALUE_SUM = 0, 1, 2, 3
LINEARITY, PLANARITY, SPHERICITY, ANISOTROPY = 4, 5, 6, 7
OMNIVARIANCE, EIGENENTROPY, SURFACE_VARIATION, VERTICALITY = 8, 9, 10, 11
SFFI_X, SFFI_Y = 12, 13
WESTIN_LINEAR, WESTIN_PLANAR, WESTIN_SPHERICAL = 14, 15, 16
NORMAL_X, NORMAL_Y, NORMAL_Z, SLOPE, ASPECT = 17, 18, 19, 20, 21
PLANE_DISTANCE, PLANE_STD, PLANE_INLIER_RATIO = 22, 23, 24
DENSITY_2D, DENSITY_3D, DENSITY_RATIO, NEIGHBOUR_RATIO, ECHO_RATIO, ECHO_RATIO_SLOPE = 25, 26, 27, 28, 29, 30
DZ_BELOW, DZ_ABOVE, Z_RANGE, Z_STD = 31, 32, 33, 34
DH_PEAKS, DH_PEAK_DISTANCE, DH_SHARE_ABOVE, DH_SHARE_BELOW = 35, 36, 37, 38
DH_ENTROPY, DH_STD, DH_SKEWNESS, DH_MAX_BIN = 39, 40, 41, 42
CENTROID_OFFSET, OCTANT_OCCUPANCY, Z_ASYMMETRY = 43, 44, 45
K1, K2, MEAN_CURVATURE, GAUSS_CURVATURE = 46, 47, 48, 49
N_NEIGHBOURS = 50
EIGENVECTOR1_X, EIGENVECTOR1_Y, EIGENVECTOR1_Z = 51, 52, 53
MSAC_NORMAL_X, MSAC_NORMAL_Y, MSAC_NORMAL_Z, MSAC_SLOPE, MSAC_ASPECT = 54, 55, 56, 57, 58
MSAC_PLANE_DISTANCE, MSAC_PLANE_STD, MSAC_INLIER_RATIO = 59, 60, 61
QUADRIC_INLIER_RATIO = 62
NSLOTS = 63
# fmt: on

#: slot number -> feature name (the name users type and the attribute name written)
NAMES: tuple[str, ...] = (
    "eigenvalue1", "eigenvalue2", "eigenvalue3", "eigenvalue_sum",
    "linearity", "planarity", "sphericity", "anisotropy",
    "omnivariance", "eigenentropy", "surface_variation", "verticality",
    "sffi_x", "sffi_y",
    "westin_linear", "westin_planar", "westin_spherical",
    "normal_x", "normal_y", "normal_z", "slope", "aspect",
    "plane_distance", "plane_std", "plane_inlier_ratio",
    "density_2d", "density_3d", "density_ratio", "neighbour_ratio", "echo_ratio", "echo_ratio_slope",
    "dz_below", "dz_above", "z_range", "z_std",
    "dh_peaks", "dh_peak_distance", "dh_share_above", "dh_share_below",
    "dh_entropy", "dh_std", "dh_skewness", "dh_max_bin",
    "centroid_offset", "octant_occupancy", "z_asymmetry",
    "k1", "k2", "mean_curvature", "gauss_curvature",
    "n_neighbours",
    "eigenvector1_x", "eigenvector1_y", "eigenvector1_z",
    "msac_normal_x", "msac_normal_y", "msac_normal_z", "msac_slope", "msac_aspect",
    "msac_plane_distance", "msac_plane_std", "msac_inlier_ratio",
    "quadric_inlier_ratio",
)
assert len(NAMES) == NSLOTS
# plane.write_plane relies on these six consecutive slots
assert (SLOPE, ASPECT, PLANE_DISTANCE) == (NORMAL_X + 3, NORMAL_X + 4, NORMAL_X + 5)
assert (MSAC_SLOPE, MSAC_ASPECT, MSAC_PLANE_DISTANCE) == (MSAC_NORMAL_X + 3, MSAC_NORMAL_X + 4, MSAC_NORMAL_X + 5)

#: feature groups (what ``--features eigen,plane`` selects)
GROUPS: dict[str, tuple[int, ...]] = {
    "eigen": tuple(range(EIGENVALUE1, SFFI_Y + 1)),
    "westin": (WESTIN_LINEAR, WESTIN_PLANAR, WESTIN_SPHERICAL),
    "plane": tuple(range(NORMAL_X, PLANE_INLIER_RATIO + 1)),
    "msac": tuple(range(MSAC_NORMAL_X, MSAC_INLIER_RATIO + 1)),
    "density": tuple(range(DENSITY_2D, ECHO_RATIO_SLOPE + 1)),
    "height": (DZ_BELOW, DZ_ABOVE, Z_RANGE, Z_STD),
    "histogram": tuple(range(DH_PEAKS, DH_MAX_BIN + 1)),
    "distribution": (CENTROID_OFFSET, OCTANT_OCCUPANCY, Z_ASYMMETRY),
    "curvature": (K1, K2, MEAN_CURVATURE, GAUSS_CURVATURE),
    "quadric": (QUADRIC_INLIER_RATIO,),
    "eigenvectors": (EIGENVECTOR1_X, EIGENVECTOR1_Y, EIGENVECTOR1_Z),
    "count": (N_NEIGHBOURS,),
}

#: slots that need the vertical-cylinder statistics of the scan
CYLINDER_SLOTS = frozenset(GROUPS["height"] + GROUPS["histogram"] + GROUPS["density"])
#: slots that need a second walk over the neighbours (after the local plane is known)
PASS2_SLOTS = frozenset(
    (PLANE_INLIER_RATIO, ECHO_RATIO_SLOPE, OCTANT_OCCUPANCY, Z_ASYMMETRY) + GROUPS["histogram"] + GROUPS["curvature"]
    + GROUPS["quadric"]
)
#: slots computed by the robust (MSAC) plane kernel
MSAC_SLOTS = frozenset(GROUPS["msac"])


@nb.njit(cache=True, inline="always")
def put(row, col, slot, value):
    """Write ``value`` into the output row at the column of ``slot``, if requested."""
    c = col[slot]
    if c >= 0:
        row[c] = value


@nb.njit(cache=True, inline="always")
def any_requested(col, first, last):
    """Is any slot of ``first..last`` requested?"""
    for sl in range(first, last + 1):
        if col[sl] >= 0:
            return True
    return False
