"""``lidarstat demo``: curvature of the agpart-like scan, written as LAS plus PNG views."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Files :func:`run_demo` writes into its folder.
DEMO_FILES = ("agpart_curvature.las", "K.png", "H.png", "chi2.png", "surface_type.png",
              "surface_type_truth.png")


def face_radius_table(scene, result):
    """Recovered cylinder radius 1/(2|median H|) per curved face of a CSG scene.

    Uses chi-square-accepted interior points (edge distance > radius). Returns a list of
    ``(face name, true radius, recovered radius, points used)``.
    """
    rows = []
    interior = _interior(scene, result) & (result["chi2_pass"] == 1)
    for fid, info in enumerate(scene.meta["faces"]):
        if info.get("kind") != "cylinder" or not info.get("n_points"):
            continue
        sel = interior & (scene.face == fid)
        true_r = float(info["radius"])
        if sel.sum() == 0:
            rows.append((info["name"], true_r, float("nan"), 0))
            continue
        h = np.median(result["H"][sel])
        rows.append((info["name"], true_r, 1.0 / (2.0 * abs(h)), int(sel.sum())))
    return rows


def _interior(scene, result):
    """Points farther from every edge than their neighbourhood's radius."""
    if "radius" in result.fields:
        return scene.edge_distance > result["radius"]
    radius = result.radius if isinstance(result.radius, float) else result.radius[0]
    return scene.edge_distance > radius


def run_demo(outdir: Path, *, sigma=0.015, radius=None, seed=0):
    """Generate the agpart-like scan, run :func:`lidarstat.features.curvature` (at the
    automatic scale unless `radius` is given), write results."""
    from ..features import curvature
    from ..io import PointCloud, write
    from ..synth import make_agpart
    from ._views import plot_field, plot_surface_types

    outdir.mkdir(parents=True, exist_ok=True)
    scene = make_agpart(sigma=sigma, rng=seed)
    res = curvature(scene.xyz, radius=radius, sigma=max(sigma, 1e-4))
    fields = {**res.to_fields(), **scene.to_fields()}
    las = outdir / "agpart_curvature.las"
    write(las, PointCloud(xyz=scene.xyz), fields=fields)
    xyz = scene.xyz
    accepted = res["chi2_pass"] == 1  # curvature is only meaningful where the model holds
    plot_field(outdir / "K.png", xyz, np.where(accepted, res["K"], np.nan),
               title="Gaussian curvature K (1/dm^2); grey: quadric rejected",
               cmap="coolwarm", symmetric=True)
    plot_field(outdir / "H.png", xyz, np.where(accepted, res["H"], np.nan),
               title="mean curvature H (1/dm), H<0 convex; grey: quadric rejected",
               cmap="coolwarm", symmetric=True)
    plot_field(outdir / "chi2.png", xyz, res["chi2_pass"].astype(float),
               title="chi-square test: 1 accepted, 0 rejected", cmap="RdYlGn", clip=(0, 100))
    plot_surface_types(outdir / "surface_type.png", xyz, res["surface_type"],
                       title="surface type (tested)")
    plot_surface_types(outdir / "surface_type_truth.png", xyz, scene.surface_type,
                       title="surface type (truth)")
    if radius is None:
        st = res.radius_stats()
        scale = (f"automatic radius {st['radius_median']:.3g} dm (median; 10-90 %: "
                 f"{st['radius_p10']:.3g}-{st['radius_p90']:.3g} dm)")
    else:
        scale = f"radius {radius} dm"
    print(f"agpart-like range scan: {len(xyz)} points, noise sigma {sigma} dm, {scale}")
    print(res.summary())
    print("cylinder radii from the median H of accepted interior points:")
    for name, true_r, r, n in face_radius_table(scene, res):
        print(f"  {name:<12s} true {true_r:.3f} dm  recovered {r:.3f} dm  ({n} points)")
    inner = _interior(scene, res)
    agree = np.mean(res["surface_type"][inner] == scene.surface_type[inner])
    print(f"surface type equals the truth on {100 * agree:.1f}% of interior points")
    print(f"wrote {las} and K.png, H.png, chi2.png, surface_type.png, surface_type_truth.png "
          f"in {outdir}")
    return res
