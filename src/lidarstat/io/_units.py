"""Linear unit of a point cloud's coordinates, from its CRS (metres, feet, US survey feet).

Methods whose parameters are lengths (windows, tile sizes, heights) state them in metres
and convert with the factors found here, so a file in feet gets the same physical
windows as a file in metres. pyproj, when installed, reads any CRS; without it the WKT
text is parsed for the unit of the coordinate axes (WKT1 ``UNIT`` of the ``PROJCS``, WKT2
``LENGTHUNIT`` of the ``CS`` axes), then the LAS GeoTIFF keys (ProjLinearUnitsGeoKey,
VerticalUnitsGeoKey) and a short list of metric EPSG codes (UTM zones, national grids);
anything else gives a warning and metres.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass

from ..errors import InvalidParameterError, LidarstatWarning

__all__ = ["LinearUnits", "linear_units", "UNIT_NAMES"]

#: Metres per unit of the names accepted by ``--units``.
UNIT_NAMES = {"metre": 1.0, "m": 1.0, "foot": 0.3048, "ft": 0.3048,
              "us-foot": 1200.0 / 3937.0, "us-ft": 1200.0 / 3937.0}


@dataclass(frozen=True)
class LinearUnits:
    """Metres per coordinate unit, horizontal and vertical.

    Attributes
    ----------
    horizontal, vertical : float
        Metres per unit of x/y and of z.
    name : str
        Unit name (``'metre'``, ``'foot'``, ``'US survey foot'`` ...).
    source : str
        ``'crs'`` (read from the CRS), ``'given'`` (``--units``/``--scale``),
        ``'none'`` (no CRS: metres assumed) or ``'assumed'`` (CRS without a readable
        unit: metres assumed, with a warning).
    """

    horizontal: float = 1.0
    vertical: float = 1.0
    name: str = "metre"
    source: str = "none"

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {"horizontal_m": self.horizontal, "vertical_m": self.vertical,
                "name": self.name, "source": self.source}


_TOKEN = re.compile(r'"(?:[^"]|"")*"|[A-Za-z_][A-Za-z0-9_]*\s*[\[(]|[\])]|[^,\[\]()"]+|,')
_UNIT_KEYS = {"UNIT", "LENGTHUNIT"}
_PROJECTED = {"PROJCS", "PROJCRS", "PROJECTEDCRS"}
_GEOGRAPHIC = {"GEOGCS", "GEOGCRS", "GEOGRAPHICCRS", "GEODCRS", "GEODETICCRS", "GEOCCS"}
_VERTICAL = {"VERT_CS", "VERTCRS", "VERTICALCRS"}


def _wkt_nodes(text):
    """(path of keywords, first string argument, first number argument) of every unit node."""
    stack, out = [], []
    for tok in _TOKEN.findall(text):
        t = tok.strip()
        if t and t[-1] in "[(" and t[0] != '"':
            stack.append([t[:-1].strip().upper(), [], ])
        elif t in ("]", ")"):
            if not stack:
                continue
            key, args = stack.pop()
            if key in _UNIT_KEYS and len(args) >= 2:
                try:
                    out.append((tuple(k for k, _ in stack), args[0], float(args[1])))
                except ValueError:
                    pass
        elif t and t != "," and stack:
            stack[-1][1].append(t.strip('"'))
    return out


def _first_key(text):
    m = re.match(r"\s*([A-Za-z_]+)\s*[\[(]", text)
    return m.group(1).upper() if m else None


def _wkt_units(text):
    """(horizontal, vertical, name) in metres from WKT text, or None if not readable."""
    top = _first_key(text)
    if top in _GEOGRAPHIC:
        return "geographic"
    nodes = _wkt_nodes(text)
    horiz = vert = None
    for path, name, factor in nodes:
        inner = [k for k in path if k in _PROJECTED | _GEOGRAPHIC | _VERTICAL]
        if not inner:
            continue
        owner = inner[-1]
        # the unit of a CRS's own axes: directly under it, or under one of its AXIS / CS
        direct = path[path.index(owner) + 1:] if owner in path else ()
        if any(k not in ("AXIS", "CS") for k in direct):
            continue  # a parameter's unit, or a unit of the base geographic CRS
        if owner in _PROJECTED and horiz is None:
            horiz = (factor, name)
        elif owner in _VERTICAL and vert is None:
            vert = factor
    if horiz is None:
        return None
    return horiz[0], (vert if vert is not None else horiz[0]), horiz[1]


def _pyproj_units(text):
    import pyproj

    crs = pyproj.CRS.from_user_input(text)
    parts = crs.sub_crs_list if crs.is_compound else [crs]
    horiz = next((c for c in parts if not c.is_vertical), None)
    vert = next((c for c in parts if c.is_vertical), None)
    if horiz is None or horiz.is_geographic:
        return "geographic"
    axis = horiz.axis_info[0]
    h = float(axis.unit_conversion_factor)
    v = float(vert.axis_info[0].unit_conversion_factor) if vert is not None else h
    return h, v, axis.unit_name


_GEOKEY_UNITS = {9001: (1.0, "metre"), 9002: (0.3048, "foot"),
                 9003: (1200.0 / 3937.0, "US survey foot")}


def _metre_epsg(code: int) -> bool:
    """Projected EPSG codes known to be in metres without pyproj (UTM zones, national grids)."""
    return (32601 <= code <= 32660 or 32701 <= code <= 32760 or 25828 <= code <= 25838
            or 26901 <= code <= 26923 or 3857 == code or code in (2154, 28992, 27700, 3035))


def _geokey_units(header):
    """(horizontal, vertical, name) from a LAS header's GeoTIFF keys, or None."""
    for vlr in list(getattr(header, "vlrs", None) or []):
        keys = {k.id: k.value_offset for k in getattr(vlr, "geo_keys", None) or []
                if k.tiff_tag_location == 0}
        if not keys:
            continue
        if 3076 in keys and keys[3076] in _GEOKEY_UNITS:  # ProjLinearUnitsGeoKey
            h, name = _GEOKEY_UNITS[keys[3076]]
        elif _metre_epsg(keys.get(3072, 0)):  # ProjectedCSTypeGeoKey
            h, name = 1.0, "metre"
        else:
            return None
        v = _GEOKEY_UNITS.get(keys.get(4099), (h, name))[0]  # VerticalUnitsGeoKey
        return h, v, name
    return None


def linear_units(crs: str | None, *, units: str | None = None, scale: float | None = None,
                 header=None, source: str | None = None) -> LinearUnits:
    """Metres per coordinate unit of a cloud, from its CRS or from the user.

    Parameters
    ----------
    crs : str or None
        The cloud's CRS (WKT or ``"EPSG:<code>"``, as :attr:`PointCloud.crs`).
    units : {'auto', 'metre', 'm', 'foot', 'ft', 'us-foot', 'us-ft'}, optional
        Force a unit (``'auto'`` or None: from the CRS).
    scale : float, optional
        Metres per coordinate unit, overriding everything else (horizontal and vertical).
    header : laspy.LasHeader, optional
        The file's header (:attr:`PointCloud.las_header`): its GeoTIFF unit keys are read
        when the CRS text alone does not give the unit (no pyproj and a bare EPSG code).
    source : str, optional
        File name used in messages.

    Returns
    -------
    LinearUnits

    Raises
    ------
    InvalidParameterError
        A geographic CRS (degrees: no fixed length per unit) without `units`/`scale`,
        an unknown unit name or a scale <= 0.

    Warns
    -----
    LidarstatWarning
        The CRS exists but its unit cannot be read (no pyproj and a bare EPSG code, or
        unreadable WKT): metres are assumed.

    Examples
    --------
    >>> wkt = ('PROJCS["NAD83 / Oregon GIC Lambert (ft)",GEOGCS["NAD83",'
    ...        'UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],'
    ...        'PARAMETER["false_easting",1312335.958],UNIT["foot",0.3048]]')
    >>> linear_units(wkt).horizontal
    0.3048
    >>> linear_units(None).source, linear_units(None, units="us-ft").name
    ('none', 'us-ft')
    """
    where = f"{source}: " if source else ""
    if scale is not None:
        if not float(scale) > 0:
            raise InvalidParameterError(f"{where}--scale must be > 0 metres per unit; got "
                                        f"{scale}")
        return LinearUnits(float(scale), float(scale), f"{float(scale):g} m", "given")
    if units not in (None, "auto"):
        if units not in UNIT_NAMES:
            raise InvalidParameterError(f"{where}unknown unit {units!r}; use one of "
                                        f"{', '.join(UNIT_NAMES)} or --scale")
        f = UNIT_NAMES[units]
        return LinearUnits(f, f, units, "given")
    if not crs:
        return LinearUnits()
    try:
        import pyproj  # noqa: F401
    except ImportError:
        got = None if str(crs).upper().startswith("EPSG:") else _wkt_units(str(crs))
        if got is None and str(crs).upper().startswith("EPSG:"):
            code = str(crs).split(":", 1)[1]
            got = (1.0, 1.0, "metre") if code.isdigit() and _metre_epsg(int(code)) else None
        if got is None and header is not None:
            got = _geokey_units(header)
    else:
        try:
            got = _pyproj_units(crs)
        except Exception:  # unreadable for pyproj: the WKT text may still say it
            got = _wkt_units(str(crs))
    if got == "geographic":
        raise InvalidParameterError(
            f"{where}the CRS is geographic (degrees), so lengths in metres have no fixed "
            "size in coordinate units; reproject the file, or give --scale (metres per "
            "unit)")
    if got is None:
        warnings.warn(f"{where}the linear unit of the CRS could not be read (pyproj is not "
                      "installed or the CRS is not WKT); assuming metres: pass --units or "
                      "--scale if that is wrong", LidarstatWarning, stacklevel=2)
        return LinearUnits(source="assumed")
    h, v, name = got
    return LinearUnits(h, v, name, "crs")
