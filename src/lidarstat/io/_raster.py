"""Rasters out: GeoTIFF (rasterio) and VRT mosaics of GeoTIFF tiles.

A raster is a :class:`Raster`: a float array of rows from north to south, the x of its
left edge, the y of its top edge, the cell size and the CRS. GeoTIFFs are written
atomically (complete or absent), DEFLATE-compressed and tiled, with NaN as no-data; a VRT
(GDAL's virtual raster, an XML file naming its tiles relative to itself) joins the GeoTIFF
tiles of a catalogue into one layer that QGIS and GDAL open as a single raster.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from .._shared._atomic import atomic_path
from ..errors import PointCloudWriteError

__all__ = ["Raster", "read_geotiff", "write_geotiff", "write_vrt"]


@dataclass(frozen=True)
class Raster:
    """A single-band raster.

    Attributes
    ----------
    values : ndarray, shape (rows, cols)
        Cell values, the first row northmost; NaN where there is no value.
    left, top : float
        x of the left edge and y of the top edge.
    resolution : float
        Cell size (square cells).
    crs : str or None
        WKT or ``EPSG:<code>``.
    """

    values: np.ndarray
    left: float
    top: float
    resolution: float
    crs: str | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(left, bottom, right, top)``."""
        rows, cols = self.values.shape
        return (self.left, self.top - rows * self.resolution,
                self.left + cols * self.resolution, self.top)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """x of the columns' centres and y of the rows' centres."""
        rows, cols = self.values.shape
        r = self.resolution
        return (self.left + r * (np.arange(cols) + 0.5), self.top - r * (np.arange(rows) + 0.5))


def _rasterio():
    try:
        import rasterio
    except ImportError:  # pragma: no cover - a declared dependency
        raise PointCloudWriteError("writing GeoTIFF needs rasterio: pip install rasterio"
                                   ) from None
    return rasterio


def write_geotiff(path: str | os.PathLike, raster: Raster) -> Path:
    """Write `raster` as a float32 GeoTIFF (DEFLATE, 256-pixel tiles, NaN no-data).

    The file appears only when complete.
    """
    rasterio = _rasterio()
    path = Path(path)
    rows, cols = raster.values.shape
    profile = dict(driver="GTiff", height=rows, width=cols, count=1, dtype="float32",
                   transform=rasterio.Affine(raster.resolution, 0.0, raster.left, 0.0,
                                             -raster.resolution, raster.top),
                   nodata=float("nan"), compress="deflate", predictor=3)
    if rows >= 256 and cols >= 256:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    if raster.crs:
        profile["crs"] = raster.crs
    with atomic_path(path) as tmp:
        try:
            with rasterio.open(tmp, "w", **profile) as dst:
                dst.write(raster.values.astype(np.float32), 1)
        except rasterio.errors.RasterioError as exc:
            raise PointCloudWriteError(f"{path}: cannot write GeoTIFF ({exc})") from exc
    return path


def read_geotiff(path: str | os.PathLike) -> Raster:
    """Read band 1 of a GeoTIFF (or VRT) written by :func:`write_geotiff` / :func:`write_vrt`."""
    rasterio = _rasterio()
    with rasterio.open(path) as src:
        values = src.read(1).astype(np.float64)
        if src.nodata is not None and not math.isnan(src.nodata):
            values[values == src.nodata] = np.nan
        t = src.transform
        crs = src.crs.to_wkt() if src.crs else None
        return Raster(values, t.c, t.f, t.a, crs)


def write_vrt(path: str | os.PathLike, tiles: list[str | os.PathLike]) -> Path:
    """A VRT mosaic of GeoTIFF tiles that share one grid (cell size and alignment).

    Tiles are listed relative to the VRT's folder; where two overlap, the later one wins.
    """
    rasterio = _rasterio()
    path = Path(path)
    infos = []
    for t in tiles:
        with rasterio.open(t) as src:
            infos.append((Path(t), src.transform, src.width, src.height,
                          src.crs.to_wkt() if src.crs else ""))
    if not infos:
        raise PointCloudWriteError(f"{path}: a mosaic needs at least one tile")
    res = infos[0][1].a
    left = min(tr.c for _, tr, _, _, _ in infos)
    top = max(tr.f for _, tr, _, _, _ in infos)
    right = max(tr.c + w * tr.a for _, tr, w, _, _ in infos)
    bottom = min(tr.f - h * res for _, tr, _, h, _ in infos)
    width, height = round((right - left) / res), round((top - bottom) / res)
    sources = []
    for tile, tr, w, h, _ in infos:
        if not math.isclose(tr.a, res, rel_tol=1e-9):
            raise PointCloudWriteError(f"{tile}: cell size {tr.a:g}, the mosaic's is {res:g}")
        x0, y0 = round((tr.c - left) / res), round((top - tr.f) / res)
        rel = os.path.relpath(tile.resolve(), path.resolve().parent)
        sources.append(
            f'    <ComplexSource>\n      <SourceFilename relativeToVRT="1">{escape(rel)}'
            f'</SourceFilename>\n      <SourceBand>1</SourceBand>\n'
            f'      <SrcRect xOff="0" yOff="0" xSize="{w}" ySize="{h}"/>\n'
            f'      <DstRect xOff="{x0}" yOff="{y0}" xSize="{w}" ySize="{h}"/>\n'
            f'      <NODATA>nan</NODATA>\n    </ComplexSource>')
    srs = f"  <SRS>{escape(infos[0][4])}</SRS>\n" if infos[0][4] else ""
    xml = (f'<VRTDataset rasterXSize="{width}" rasterYSize="{height}">\n{srs}'
           f"  <GeoTransform>{left!r}, {res!r}, 0.0, {top!r}, 0.0, {-res!r}</GeoTransform>\n"
           f'  <VRTRasterBand dataType="Float32" band="1">\n'
           f"    <NoDataValue>nan</NoDataValue>\n" + "\n".join(sources) +
           "\n  </VRTRasterBand>\n</VRTDataset>\n")
    with atomic_path(path) as tmp:
        Path(tmp).write_text(xml)
    return path
