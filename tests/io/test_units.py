"""Linear units from the CRS (pyproj or the WKT text), user overrides, bad input."""

import sys

import pytest

from lidarstat.errors import InvalidParameterError, LidarstatWarning
from lidarstat.io import linear_units, read

from conftest import shared_file

US_FT = 1200 / 3937
# WKT1 with parameters in metres but the projected axes in US survey feet: only the
# PROJCS's own UNIT counts.
WKT1_USFT = (
    'PROJCS["NAD83 / Texas South Central (ftUS)",GEOGCS["NAD83",DATUM["North_American_'
    'Datum_1983",SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],'
    'UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],'
    'PARAMETER["false_easting",600000],UNIT["US survey foot",0.304800609601219,'
    'AUTHORITY["EPSG","9003"]],AXIS["Easting",EAST],AXIS["Northing",NORTH]]')
WKT2_FT = (
    'PROJCRS["NAD83(HARN) / Oregon GIC Lambert (ft)",BASEGEOGCRS["NAD83(HARN)",'
    'ANGLEUNIT["degree",0.0174532925199433]],CONVERSION["Oregon GIC Lambert (ft)",'
    'METHOD["Lambert Conic Conformal (2SP)"],PARAMETER["False easting",400000,'
    'LENGTHUNIT["metre",1]]],CS[Cartesian,2],AXIS["easting (X)",east,ORDER[1],'
    'LENGTHUNIT["foot",0.3048]],AXIS["northing (Y)",north,ORDER[2],LENGTHUNIT["foot",0.3048]]]')
COMPOUND = (
    'COMPD_CS["UTM 32N + height (ftUS)",PROJCS["WGS 84 / UTM zone 32N",GEOGCS["WGS 84",'
    'UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],UNIT["metre",1]],'
    'VERT_CS["NAVD88 height (ftUS)",VERT_DATUM["North American Vertical Datum 1988",2005],'
    'UNIT["US survey foot",0.304800609601219]]]')
GEOGRAPHIC = 'GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],' \
             'UNIT["degree",0.0174532925199433]]'


@pytest.fixture(params=["pyproj", "wkt-text"])
def parser(request, monkeypatch):
    """Run each case with pyproj (when installed) and with the fallback WKT parser."""
    if request.param == "pyproj":
        pytest.importorskip("pyproj", reason="pyproj reads the CRS when installed")
    else:
        monkeypatch.setitem(sys.modules, "pyproj", None)  # import pyproj -> ImportError
    return request.param


@pytest.mark.parametrize("wkt, h, v, name", [
    (WKT1_USFT, US_FT, US_FT, "US survey foot"),
    (WKT2_FT, 0.3048, 0.3048, "foot"),
    (COMPOUND, 1.0, US_FT, "metre"),
])
def test_units_from_wkt(parser, wkt, h, v, name):
    u = linear_units(wkt)
    assert u.horizontal == pytest.approx(h, rel=1e-12)
    assert u.vertical == pytest.approx(v, rel=1e-12)
    assert u.name == name and u.source == "crs"


def test_geographic_crs_is_refused(parser):
    with pytest.raises(InvalidParameterError, match="geographic"):
        linear_units(GEOGRAPHIC, source="a.las")
    assert linear_units(GEOGRAPHIC, scale=111_000.0).horizontal == 111_000.0


def test_real_files(parser):
    autzen = read(shared_file("pdal_testdata/autzen_trim.laz"))
    assert linear_units(autzen.crs, header=autzen.las_header).horizontal == pytest.approx(0.3048)
    utm = read(shared_file("isprs_filtertest/joined/samp11_ref_intensity.laz"))
    assert linear_units(utm.crs, header=utm.las_header).horizontal == 1.0


def test_overrides_and_missing_crs():
    assert linear_units(None).source == "none"
    assert linear_units(WKT2_FT, units="metre").horizontal == 1.0
    assert linear_units(None, units="us-ft").vertical == pytest.approx(US_FT)
    assert linear_units(WKT2_FT, scale=2.0).source == "given"
    with pytest.raises(InvalidParameterError, match="scale"):
        linear_units(None, scale=0)
    with pytest.raises(InvalidParameterError, match="unknown unit"):
        linear_units(None, units="yard")


def test_unreadable_unit_warns_and_assumes_metres(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyproj", None)
    with pytest.warns(LidarstatWarning, match="assuming metres"):
        u = linear_units("EPSG:2994", source="f.las")
    assert (u.horizontal, u.source) == (1.0, "assumed")


def test_geotiff_keys_without_pyproj(monkeypatch):
    from types import SimpleNamespace as NS

    monkeypatch.setitem(sys.modules, "pyproj", None)
    key = lambda i, v: NS(id=i, value_offset=v, tiff_tag_location=0)  # noqa: E731
    header = NS(vlrs=[NS(geo_keys=[key(1024, 1), key(3072, 2994), key(3076, 9002),
                                   key(4099, 9003)])])
    u = linear_units("EPSG:2994", header=header)
    assert (u.horizontal, u.vertical, u.name) == (0.3048, pytest.approx(US_FT), "foot")
    assert linear_units("EPSG:32632").horizontal == 1.0  # a UTM zone: metres
