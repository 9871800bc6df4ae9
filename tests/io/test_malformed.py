"""Hostile and malformed files: one-line errors naming the file and the field, before any
allocation; the streaming reader and ``describe`` share ``read``'s checks."""

from __future__ import annotations

import math
import struct
import time
import zipfile

import laspy
import numpy as np
import pytest
from fuzz_mutants import rewrite_e57_xml, variable_chunk_laz
from laspy.vlrs.vlrlist import VLRList

import lidarstat.io as lio
from lidarstat.cli import main
from lidarstat.errors import (
    InvalidParameterError,
    InvalidPointsError,
    MalformedFileError,
    PointCloudReadError,
)
from lidarstat.io._las_checks import MAX_READ_ENV, read_ceiling

N = 500
UTM = np.array([431_000.0, 5_400_000.0, 0.0])


def _las(path, version="1.4", pf=6, n=N, evlr=False):
    header = laspy.LasHeader(version=version, point_format=pf)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = UTM
    header.vlrs.append(laspy.VLR(user_id="t", record_id=1, description="d", record_data=b"v" * 9))
    if evlr:
        header.evlrs = VLRList([laspy.VLR(user_id="t", record_id=2, description="e",
                                          record_data=b"e" * 12)])
    las = laspy.LasData(header)
    rng = np.random.default_rng(3)
    if n:
        xyz = UTM + rng.uniform(0, 100, (n, 3))
        las.x, las.y, las.z = xyz.T
    las.write(path)
    return path


def _patch(src, dst, offset, fmt, value):
    data = bytearray(src.read_bytes())
    struct.pack_into("<" + fmt, data, offset, value)
    dst.write_bytes(bytes(data))
    return dst


def _one_line(exc, path):
    msg = str(exc.value)
    assert "\n" not in msg and str(path) in msg, msg
    return msg


def _u(data, offset, fmt):
    return struct.unpack_from("<" + fmt, data, offset)[0]


# ------------------------------------------------------------------- LAS header fields
@pytest.mark.parametrize(("offset", "fmt", "value", "expected"), [
    (96, "I", 99_999_999, (r"offset_to_point_data 99999999 lies beyond the end of the file "
                           r"\(\d+ bytes\)")),
    (100, "I", 2**31, r"number_of_vlrs 2147483648 needs at least"),
    (94, "H", 100, r"header_size 100 is smaller than the 375 bytes of a LAS 1.4 header"),
    (104, "B", 37, r"point_format 37 is not a LAS point format"),
    (105, "H", 10, r"point_record_length 10 is smaller than the 30 bytes of point format 6"),
    (247, "Q", 10**6, r"point count 1000000 x point_record_length 30"),
    (131, "d", 0.0, r"x scale 0\.0 must be finite, non-zero"),
    (139, "d", math.nan, r"y scale nan must be finite"),
    (147, "d", 1e306, r"z scale 1e\+306 must be finite"),
    (155, "d", math.inf, r"x offset inf is not finite"),
    (163, "d", -1e300, r"y offset -1e\+300 puts every coordinate beyond 1e\+15 in magnitude"),
    (243, "I", 2**32 - 1, r"number_of_evlrs 4294967295 needs at least"),
    (235, "Q", 2**60, r"start_of_first_evlr 1152921504606846976 lies outside"),
])
def test_las_header_fields_are_checked(tmp_path, offset, fmt, value, expected):
    good = _las(tmp_path / "good.las", evlr=True)
    bad = _patch(good, tmp_path / "scan.las", offset, fmt, value)
    for call in (lio.read, lio.describe, lambda p: list(lio.iter_chunks(p, 100))):
        with pytest.raises(MalformedFileError, match=r"scan\.las: unreadable LAS file \(malformed (header|VLR|EVLR): "
                           + expected) as exc:
            call(bad)
        _one_line(exc, bad)


def test_huge_vlr_count_fails_fast(tmp_path):
    good = _las(tmp_path / "good.las", version="1.2", pf=1, n=3)
    bad = _patch(good, tmp_path / "vlrs.las", 100, "I", 2**32 - 1)
    start = time.perf_counter()
    with pytest.raises(MalformedFileError, match="number_of_vlrs 4294967295"):
        lio.read(bad)
    assert time.perf_counter() - start < 1.0


def test_vlr_record_length_past_point_data(tmp_path):
    good = _las(tmp_path / "good.las")
    header_size = _u(good.read_bytes(), 94, "H")
    bad = _patch(good, tmp_path / "vlr.las", header_size + 20, "H", 60000)
    with pytest.raises(MalformedFileError, match=r"VLR 0 \('t', record 1\) has record_length "
                                                 r"60000, which runs past offset_to_point_data"):
        lio.read(bad)


# ------------------------------------------------------------------- LAZ chunk table
def test_laz_chunk_table_pointer_and_count(tmp_path):
    good = _las(tmp_path / "good.laz")
    data = good.read_bytes()
    start = _u(data, 96, "I")
    table = _u(data, start, "q")
    cases = [(start, "q", 2**40, (r"its offset 1099511627776 lies outside the file's point "
                                  r"data")),
             (start, "q", 3, r"its offset 3 lies outside"),
             (table + 4, "I", 2**32 - 1, (r"4294967295 chunks announced for \d+ bytes of "
                                          r"compressed points")),
             (table + 4, "I", 0, r"0 chunks announced")]
    for i, (offset, fmt, value, expected) in enumerate(cases):
        bad = _patch(good, tmp_path / f"scan{i}.laz", offset, fmt, value)
        for call in (lio.read, lio.describe, lambda p: list(lio.iter_chunks(p, 100))):
            with pytest.raises(MalformedFileError, match=rf"scan{i}\.laz: unreadable LAZ file \(malformed "
                                                          r"chunk table: "
                               + expected) as exc:
                call(bad)
            _one_line(exc, bad)


def test_laz_layer_sizes_beyond_their_chunk(tmp_path):
    good = _las(tmp_path / "good.laz", pf=7)  # layered chunks: 9 point layers + RGB
    start = _u(good.read_bytes(), 96, "I")
    bad = _patch(good, tmp_path / "layer.laz", start + 8 + 36 + 4, "I", 3_000_000_000)
    with pytest.raises(MalformedFileError, match=r"layer\.laz: unreadable LAZ file \(malformed "
                                                 r"chunk: chunk 0 "
                                                 r"announces \d+ bytes of layers, but the chunk "
                                                 r"table gives it \d+ bytes"):
        lio.read(bad)


def test_laz_variable_size_chunks(tmp_path):
    xyz = UTM + np.random.default_rng(4).uniform(0, 100, (N, 3)).round(3)
    good = variable_chunk_laz(tmp_path / "var.laz", xyz)
    np.testing.assert_allclose(lio.read(good).xyz, xyz, atol=5e-4, rtol=0)
    assert sum(len(c) for c in lio.iter_chunks(good, 64)) == N
    bad = _patch(good, tmp_path / "count.laz", 107, "I", N + 1)
    with pytest.raises(MalformedFileError, match=rf"count\.laz: unreadable LAZ file \(malformed "
                                                 rf"chunk table: its chunks hold {N} points, "
                                                 rf"the header {N + 1}"):
        lio.read(bad)


def test_laz_point_count_beyond_chunks(tmp_path):
    good = _las(tmp_path / "good.laz")
    bad = _patch(good, tmp_path / "count.laz", 247, "Q", 10**12)
    with pytest.raises(MalformedFileError, match=r"count\.laz: unreadable LAZ file \(malformed header: "
                                                 r"point "
                                                 r"count 1000000000000 exceeds 1 chunks"):
        list(lio.iter_chunks(bad))


# ------------------------------------------------------------------- streaming = whole
def test_streaming_reader_refuses_what_read_refuses(tmp_path):
    empty = _las(tmp_path / "empty.las", n=0)
    for call in (lio.read, lambda p: next(lio.iter_chunks(p))):
        with pytest.raises(InvalidPointsError, match=r"empty\.las: empty point cloud"):
            call(empty)
    good = _las(tmp_path / "good.las", version="1.2", pf=3)
    short = _patch(good, tmp_path / "short.las", 107, "I", N + 1)
    for call in (lio.read, lambda p: list(lio.iter_chunks(p, 100))):
        with pytest.raises(MalformedFileError, match=r"short\.las: unreadable LAS file \(malformed "
                                                     r"header: point "
                                                     rf"count {N + 1} x point_record_length 34"):
            call(short)


def test_describe_still_reports_an_empty_file(tmp_path):
    d = lio.describe(_las(tmp_path / "empty.las", n=0))
    assert d["point_count"] == 0


@pytest.mark.parametrize(("offset", "value", "shown"), [
    (131, 0.0, "x scale 0.0"), (139, math.nan, "y scale nan"), (147, 1e306, "z scale 1e+306"),
    (155, math.inf, "x offset inf")])
def test_cli_info_refuses_bad_scales(tmp_path, capsys, offset, value, shown):
    bad = _patch(_las(tmp_path / "good.las"), tmp_path / "scan.las", offset, "d", value)
    code = main(["info", str(bad)])
    err = capsys.readouterr().err.strip()
    assert code != 0 and len(err.splitlines()) == 1
    assert "scan.las: unreadable LAS file (malformed header: " + shown in err


# ------------------------------------------------------------------- read ceiling
def test_read_ceiling(tmp_path, monkeypatch):
    path = _las(tmp_path / "big.las")
    with pytest.raises(MalformedFileError, match=r"big\.las: reading 500 points of 30 bytes "
                                                 r"needs about .* more than the read ceiling "
                                                 r"of 1000 bytes"):
        lio.read(path, max_bytes=1000)
    assert len(lio.read(path, max_bytes=10**6)) == N
    # The streaming reader needs only one chunk at a time.
    assert sum(len(c) for c in lio.iter_chunks(path, 10, max_bytes=2000)) == N
    monkeypatch.setenv(MAX_READ_ENV, "1000")
    assert read_ceiling() == 1000
    with pytest.raises(MalformedFileError, match="read ceiling of 1000 bytes"):
        lio.read(path)
    for bad in ("lots", "inf", "0", "-5"):
        monkeypatch.setenv(MAX_READ_ENV, bad)
        with pytest.raises(InvalidParameterError, match=MAX_READ_ENV):
            lio.read(path)
    monkeypatch.setenv(MAX_READ_ENV, "1e6")
    assert read_ceiling() == 10**6 and read_ceiling(np.int64(7)) == 7
    with pytest.raises(InvalidParameterError, match="max_bytes"):
        lio.read(path, max_bytes=-1)
    monkeypatch.delenv(MAX_READ_ENV)
    assert read_ceiling() > 2**28  # half of the physical memory


def test_read_ceiling_other_formats(tmp_path):
    xyz = UTM + np.random.default_rng(1).uniform(0, 10, (N, 3))
    for suffix in (".ply", ".npz", ".csv"):
        path = tmp_path / f"c{suffix}"
        lio.write(path, lio.PointCloud(xyz))
        with pytest.raises(MalformedFileError, match=rf"c\{suffix}: reading .* read ceiling"):
            lio.read(path, max_bytes=1000)
        np.testing.assert_array_equal(lio.read(path).xyz, xyz)


# ------------------------------------------------------------------- other formats
def _write_xyz(path, xyz):
    if path.suffix == ".csv":
        path.write_text("x,y,z\n" + "\n".join(",".join(repr(v) for v in r) for r in xyz.tolist()))
    else:
        np.savez(path, xyz=xyz)
    return path


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_huge_and_nonfinite_coordinates(tmp_path, suffix):
    xyz = np.array([[1.0, 2.0, 3.0], [1.5e308, 0.0, 0.0], [-1.5e308, 1.0, 1.0], [4, 5, 6]])
    path = _write_xyz(tmp_path / f"huge{suffix}", xyz)
    with pytest.raises(InvalidPointsError, match=rf"huge\{suffix}: `xyz` has 2 points with a "
                                                 r"coordinate beyond 1e\+15 in magnitude "
                                                 r"\(first at index 1"):
        lio.read(path)
    xyz[1, 2], xyz[2, 0] = np.nan, np.inf
    nan = _write_xyz(tmp_path / f"nan{suffix}", xyz)
    with pytest.raises(InvalidPointsError, match=rf"nan\{suffix}: `xyz` has 2 points with NaN "
                                                 r"or infinite coordinates \(first at index 1\)"):
        lio.read(nan)


def test_npz_strings_objects_and_shapes(tmp_path):
    cases = {"str": ({"xyz": np.array([["1", "2", "x"]] * 4)}, r"coordinates hold <U1 values"),
             "obj": ({"xyz": np.array([[object(), 1, 2]], dtype=object)},
                     r"array 'xyz' holds Python objects, which need pickle; refused"),
             "shape": ({"xyz": np.zeros((4, 2))},
                       r"array 'xyz' has shape \(4, 2\); expected \(N, 3\)"),
             "cols": ({"x": np.zeros(4), "y": np.zeros(3), "z": np.zeros(4)},
                      r"arrays x, y, z must be 1-D of equal length")}
    for name, (arrays, expected) in cases.items():
        path = tmp_path / f"{name}.npz"
        np.savez(path, allow_pickle=True, **arrays)
        with pytest.raises(PointCloudReadError, match=rf"{name}\.npz: .*{expected}") as exc:
            lio.read(path)
        _one_line(exc, path)


def test_npz_header_announcing_more_than_stored(tmp_path):
    path = tmp_path / "shape.npz"
    np.savez(path, xyz=np.zeros((300, 3)))
    with zipfile.ZipFile(path) as zf:
        data = zf.read("xyz.npy")
    hlen = _u(data, 8, "H")  # format 1.0: magic, version, u2 header length, header text
    text = "{'descr': '<f8', 'fortran_order': False, 'shape': (9999999, 3), }"
    data = data[:10] + text.ljust(hlen - 1).encode() + b"\n" + data[10 + hlen:]
    hacked = tmp_path / "hacked.npz"
    with zipfile.ZipFile(hacked, "w") as zf:
        zf.writestr("xyz.npy", data)
    with pytest.raises(MalformedFileError, match=r"hacked\.npz: unreadable NPZ file \(malformed "
                                                 r"array header: 'xyz' "
                                                 r"announces shape \(9999999, 3\)"):
        lio.read(hacked)


def test_ply_counts_types_and_garbage(tmp_path):
    xyz = UTM + np.random.default_rng(2).uniform(0, 10, (50, 3))
    good = tmp_path / "good.ply"
    lio.write(good, lio.PointCloud(xyz))
    data = good.read_bytes()
    (tmp_path / "count.ply").write_bytes(data.replace(b"element vertex 50",
                                                      b"element vertex 5000000000"))
    with pytest.raises(MalformedFileError, match=r"count\.ply: unreadable PLY file \(malformed "
                                                 r"header: element "
                                                 r"'vertex' announces 5000000000 rows of at "
                                                 r"least 24 bytes, but 1200 bytes follow"):
        lio.read(tmp_path / "count.ply")
    (tmp_path / "list.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty list uchar float x\n"
        "property float y\nproperty float z\nend_header\n2 1 2 3 4\n1 5 6 7\n")
    with pytest.raises(MalformedFileError, match=r"list\.ply: unreadable PLY file \(malformed "
                                                 r"header: coordinate "
                                                 r"property 'x' is a list"):
        lio.read(tmp_path / "list.ply")
    (tmp_path / "junk.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n1 2 3\nfoo bar baz\n")
    with pytest.raises(PointCloudReadError, match=r"junk\.ply: unreadable PLY file") as exc:
        lio.read(tmp_path / "junk.ply")
    _one_line(exc, tmp_path / "junk.ply")


def test_text_ragged_nonnumeric_and_binary(tmp_path):
    cases = {"ragged.csv": ("x,y,z\n1,2,3\n1,2\n", r"line 3 has 2 values; the header names 3"),
             "word.csv": ("x,y,z\n1,2,3\n1,two,3\n", r"non-numeric value"),
             "noxyz.txt": ("a b c\n1 2 3\n", r"no column named x/y/z")}
    for name, (text, expected) in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(PointCloudReadError, match=rf"{name}: .*{expected}"):
            lio.read(tmp_path / name)
    (tmp_path / "bin.csv").write_bytes(b"x,y,z\n\xff\xfe\x00\x01\n")
    with pytest.raises(PointCloudReadError, match=r"bin\.csv: unreadable CSV file"):
        lio.read(tmp_path / "bin.csv")


def test_e57_garbage(tmp_path):
    pytest.importorskip("pye57")
    path = tmp_path / "junk.e57"
    path.write_bytes(b"ASTM-E57" + bytes(range(256)) * 8)
    with pytest.raises(PointCloudReadError, match=r"junk\.e57: unreadable E57 file") as exc:
        lio.read(path)
    _one_line(exc, path)


def test_e57_record_count_beyond_the_data(tmp_path):
    pye57 = pytest.importorskip("pye57")
    path = tmp_path / "scan.e57"
    xyz = UTM + np.random.default_rng(5).uniform(0, 10, (300, 3))
    e57 = pye57.E57(str(path), mode="w")
    e57.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1],
                        "cartesianZ": xyz[:, 2]})
    e57.close()
    # pye57 writes single-precision coordinates.
    np.testing.assert_array_equal(lio.read(path).xyz, xyz.astype(np.float32))
    bad = tmp_path / "count.e57"
    bad.write_bytes(rewrite_e57_xml(path.read_bytes(), lambda x: x.replace(
        'recordCount="300"', 'recordCount="999999"')))
    # pye57 alone returns 999999 points, the last 999699 of them uninitialised memory.
    with pytest.raises(PointCloudReadError, match=r"count\.e57: unreadable E57 file \(scan 0 "
                                                  r"announces 999999 points in recordCount, "
                                                  r"300 found\)"):
        lio.read(bad)
