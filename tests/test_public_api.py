"""The public surface: cheap top-level import, stable names."""

import subprocess
import sys

import lidarstat


def test_import_is_cheap():
    code = ("import sys, lidarstat; "
            "bad = [m for m in ('numba', 'scipy', 'matplotlib', 'laspy') if m in sys.modules]; "
            "print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_public_names():
    assert {"io", "neighbors", "features", "stats", "classify", "synth", "cli", "read", "write",
            "curvature"} <= set(lidarstat.__all__)
    assert callable(lidarstat.read) and callable(lidarstat.curvature)
    from lidarstat import features, neighbors, stats

    assert {"curvature", "fit_quadrics", "optimal_bandwidth", "estimate_sigma",
            "FitStatus"} <= set(features.__all__)
    assert {"Neighborhoods", "radius_neighbors", "knn_neighbors"} <= set(neighbors.__all__)
    assert {"variance_test_satterthwaite", "wald_test", "z_test"} <= set(stats.__all__)
    from lidarstat import segment

    assert {"Segmentation", "Polylines", "components", "grow_regions", "relabel", "adjacency",
            "hoover", "binary_scores"} <= set(segment.__all__)


def test_contract_field_names():
    from lidarstat.features import FIELDS

    contract = ["neighbors", "z0", "sigma0_sq", "chi2_pass", "K", "H", "kmin", "kmax", "K_sig",
                "H_sig", "surface_type"]
    assert list(FIELDS)[: len(contract)] == contract
    assert all(len(name) <= 32 for name in FIELDS)  # LAS extra-bytes name limit
