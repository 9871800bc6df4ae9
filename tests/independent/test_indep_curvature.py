"""`curvature` with its defaults on the independent surface family (issue 17).

* surface type right on >= 90 % of the interior points where the tests have power,
  pooled over a seed sweep, for planes, spheres, cylinders, cones and tori at random
  orientations (steep and overhanging included), z noise and range noise from a sensor;
* each test's size within its binomial interval under its null, on flat, steep and
  overhanging faces of a z-noise cloud alike, in the pca and auto frames;
* the noise sigma estimated along its direction within a few per cent.
"""

from __future__ import annotations

import numpy as np
import pytest
from indep_surfaces import KINDS, lattice, make_surface

from lidarstat.features import curvature, estimate_sigma, optimal_bandwidth
from lidarstat.stats import z_critical

SEEDS = range(3)
HALF = 26  # patches of 53 x 53 points
ALPHA = 0.05
TOP = 12.0  # the automatic ladder's largest radius, in point spacings


def _powered(surface, power=0.9):
    """Points where the tests have power at the ladder's top radius: |H| and every non-zero
    principal curvature at least their minimal detectable values (eq. 19, power 0.9) for
    the noise seen along the true normal."""
    s = surface.spacing
    design = optimal_bandwidth(K0=0.0, H0=-1.0, sigma=1.0, density=1.0 / s ** 2,
                               radii=[TOP * s], power=power)
    h_unit = float(design.H_min[0])
    if surface.noise == "z":
        d = np.array([0.0, 0.0, 1.0])
        dn = np.abs(surface.normal @ d)
    else:
        ray = surface.xyz - surface.sensor
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        dn = np.abs(np.einsum("ij,ij->i", ray, surface.normal))
    h_min = h_unit * surface.sigma * np.maximum(dn, 0.1)
    k1, k2 = surface.k1, surface.k2
    H = 0.5 * (k1 + k2)
    flat = (k1 == 0) & (k2 == 0)
    ok_h = np.abs(H) >= h_min
    ok_k = ((k1 == 0) | (np.abs(k1) >= 1.5 * h_min)) & ((k2 == 0) | (np.abs(k2) >= 1.5 * h_min))
    return flat | (ok_h & ok_k)


@pytest.mark.parametrize("noise", ["z", "range"])
@pytest.mark.parametrize("kind", KINDS)
def test_surface_type_at_defaults(kind, noise):
    right = total = 0
    for seed in SEEDS:
        s = make_surface(kind, seed, noise=noise, half=HALF)
        res = curvature(s.xyz, sensor=s.sensor)  # the defaults: no radius, no sigma
        assert res.automatic and "radius" in res.fields
        keep = (s.border > (TOP + 0.5) * s.spacing) & _powered(s)
        nrm = np.c_[res["NormalX"], res["NormalY"], res["NormalZ"]]
        truth = s.oriented_types(nrm)
        right += int((res["surface_type"][keep] == truth[keep]).sum())
        total += int(keep.sum())
    assert total > 500
    assert right / total >= 0.90, f"{kind}, {noise} noise: {right / total:.3f} right"


def _binomial_interval(p, n, level=0.999):
    z = z_critical(1 - level)
    sd = np.sqrt(p * (1 - p) / n)
    return p - z * sd, p + z * sd


#: Largest truncation bias of a neighbourhood's quadric, per degree of freedom and in
#: units of the height noise variance, at which the quadric counts as the true model.
NULL_BIAS = 0.03


def _rates(kind, tilt, frame):
    """Rejection rates of the four tests at a fixed radius, on neighbourhoods far enough
    apart to be independent, over a seed sweep of z-noise patches at `tilt`.

    On curved surfaces the tests' null (the quadric holds in the fit's frame) is checked
    on a noise-free twin of each patch (the same points without their noise): a
    neighbourhood counts when the chi-square of the twin's residuals against
    ``NULL_BIAS`` times the height variance is below its median, i.e. when the quadric's
    own truncation error is far below the noise. Elsewhere a rejection is the test's
    power, not its size.
    """
    rej = {"chi2": [], "planarity": [], "H": [], "K": []}
    for seed in range(16):
        seed = 1000 * tilt + seed
        s = make_surface(kind, seed, tilt=tilt, half=40)
        b = 3.5 * s.spacing
        q = lattice(s, 2.2 * b)
        holds = np.ones(q.size, bool)
        if kind != "plane":
            twin = make_surface(kind, seed, tilt=tilt, half=40, sigma=1e-9 * s.sigma)
            s = make_surface(kind, seed, tilt=tilt, half=40, sigma=s.sigma)
            bias = curvature(twin.xyz, radius=b, sigma=np.sqrt(NULL_BIAS) * s.sigma,
                             frame=frame)
            holds = bias["chi2_p"][q] >= 0.5
        res = curvature(s.xyz, radius=b, sigma=s.sigma, frame=frame)
        q = q[holds]
        ok = res["chi2_pass"][q] == 1
        rej["chi2"].append(res["chi2_p"][q] < ALPHA)
        rej["planarity"].append(res["planar_p"][q][ok] < ALPHA)
        rej["H"].append(res["H_p"][q][ok] < ALPHA / 2)
        rej["K"].append(res["K_p"][q][ok] < ALPHA / 2)
    return {k: np.concatenate(v) for k, v in rej.items()}


@pytest.mark.parametrize("frame", ["pca", "auto"])
@pytest.mark.parametrize("tilt", [10, 75, 105])
def test_test_sizes_on_planes(frame, tilt):
    """Planes, z noise, flat (10 deg), steep (75) and overhanging (105): chi-square and
    planarity at alpha, H at alpha/2."""
    rej = _rates("plane", tilt, frame)
    for name, nominal in (("chi2", ALPHA), ("planarity", ALPHA), ("H", ALPHA / 2)):
        lo, hi = _binomial_interval(nominal, rej[name].size)
        assert lo <= rej[name].mean() <= hi, (name, rej[name].mean(), rej[name].size)


@pytest.mark.parametrize("frame", ["pca", "auto"])
@pytest.mark.parametrize("tilt", [10, 75, 105])
def test_test_sizes_on_cylinders(frame, tilt):
    """Cylinders (K = 0 with one principal curvature far from 0), z noise: the chi-square
    at alpha and the K test at alpha/2, on flat, steep and overhanging patches, where the
    quadric holds in the fit's frame (``_rates``). In the auto frame on the overhanging
    patches it does not hold on about a quarter of the neighbourhoods: where z runs
    nearly inside the tangent plane the height noise along the axis frame,
    sigma |d.n| / |e.n|, is tiny and the quadric's truncation error in a frame oblique to
    the surface exceeds it (docs/methods/curvature.md)."""
    rej = _rates("cylinder", tilt, frame)
    assert rej["chi2"].size >= 600
    for name, nominal in (("chi2", ALPHA), ("K", ALPHA / 2)):
        lo, hi = _binomial_interval(nominal, rej[name].size)
        assert lo <= rej[name].mean() <= hi, (name, rej[name].mean(), rej[name].size)


@pytest.mark.parametrize("noise", ["z", "range"])
@pytest.mark.parametrize("kind,tilt", [("plane", 10), ("plane", 80), ("cylinder", 70),
                                       ("sphere", None)])
def test_sigma_estimated_along_the_noise_direction(kind, tilt, noise):
    est = []
    for seed in range(4):
        s = make_surface(kind, 77 + seed, noise=noise, tilt=tilt, half=30)
        est.append(estimate_sigma(s.xyz, 3.0 * s.spacing, noise=noise, sensor=s.sensor)
                   / s.sigma)
    assert np.mean(est) == pytest.approx(1.0, abs=0.05), est


def test_frame_z_kept_for_flat_faces():
    """The paper's z frame stays available and right where heights are a function of xy."""
    s = make_surface("sphere", 3, tilt=5, half=30)
    res = curvature(s.xyz, frame="z")
    keep = (s.border > (TOP + 0.5) * s.spacing) & _powered(s)
    truth = s.oriented_types(np.c_[res["NormalX"], res["NormalY"], res["NormalZ"]])
    assert (res["surface_type"][keep] == truth[keep]).mean() >= 0.9


@pytest.mark.slow
def test_segment_hoover_every_surface():
    """`segment --method curvature` with its defaults on the independent machined parts
    (``indep_parts.py``: flanged and bored parts at random tilts, range images with z
    noise, terrestrial scans with range noise): Hoover correct detection (T = 0.8) of at
    least 90 % of the faces of 300 points or more, pooled over a seed sweep."""
    import indep_parts as ip

    from lidarstat.segment import segment_curvature

    correct = total = 0
    for seed in range(2):
        rng = np.random.default_rng(1000 + seed)
        for gen in (ip.range_image, ip.tls_scan):
            for kind in ("flange", "block"):
                scan = gen(rng, kind)
                seg = segment_curvature(scan.points, sensor=scan.sensor)
                c, n = ip.hoover_counts(scan, seg.labels)
                correct += c
                total += n
    assert correct / total >= 0.9, (correct, total)
