"""LAS extra bytes as PDAL's writers.las records them: a description, no no-data, no min/max."""

from __future__ import annotations

import laspy
import numpy as np
import pytest

import lidarstat.classify  # noqa: F401  (registers the classification's field descriptions)
import lidarstat.io as lio
from lidarstat.io._descriptions import field_description, shorten

N = 120


def _records(path) -> dict[str, object]:
    """The extra-bytes records of `path`, read with plain laspy, by name."""
    vlr = laspy.read(path).header.vlrs.get("ExtraBytesVlr")[0]
    return {r.name.decode(): r for r in vlr.extra_bytes_structs}


def _fields(rng):
    plane_p = rng.random(N)
    plane_p[::4] = np.nan  # no value: not tested
    return {"plane_p": plane_p, "point_class": rng.integers(0, 4, N).astype(np.uint8),
            "neighbors": np.arange(N, dtype=np.int32), "my_score": rng.normal(size=N),
            "a_long_but_legal_name_of_32_ch_x": np.ones(N, np.float32)}


def _check(path, fields):
    records = _records(path)
    assert set(fields) <= set(records)
    assert records["plane_p"].description == b"p-value of chi-square plane test"
    assert records["point_class"].description == b"0 undetermined,1 surface,2 edge"
    assert records["my_score"].description == b"lidarstat field my_score"
    assert records["a_long_but_legal_name_of_32_ch_x"].description == (
        b"a_long_but_legal_name_of_32_ch_x")
    for name in fields:
        r = records[name]
        assert 0 < len(r.description) <= 32
        assert r.no_data is None and r.options == 0, name  # no no_data, min or max: as PDAL
    back = laspy.read(path)
    for name, values in fields.items():
        np.testing.assert_array_equal(back[name], values)  # NaN where NaN


def test_extra_bytes_have_descriptions_and_no_no_data(tmp_path, rng):
    cloud = lio.PointCloud(rng.random((N, 3)) * 10)
    fields = _fields(rng)
    for suffix in (".las", ".laz"):
        out = tmp_path / f"o{suffix}"
        lio.write(out, cloud, fields=fields)
        _check(out, fields)


def test_streamed_extra_bytes_match(tmp_path, rng):
    src = tmp_path / "src.las"
    lio.write(src, lio.PointCloud(rng.random((N, 3)) * 10))
    fields = _fields(rng)
    out = tmp_path / "streamed.laz"
    lio.rewrite(src, out, lambda start, chunk: {k: v[start:start + len(chunk)]
                                                 for k, v in fields.items()},
                points_per_chunk=50)
    _check(out, fields)


def test_existing_extra_bytes_keep_their_description(tmp_path, rng):
    src = tmp_path / "src.las"
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.add_extra_dims([laspy.ExtraBytesParams(name="theirs", type="f4",
                                                  description="from another tool")])
    las = laspy.LasData(header)
    las.x, las.y, las.z = rng.random((3, N))
    las.theirs = np.ones(N, np.float32)
    las.write(src)
    out = tmp_path / "o.las"
    lio.write(out, lio.read(src), fields={"plane_p": rng.random(N)})
    records = _records(out)
    assert records["theirs"].description == b"from another tool"
    assert records["theirs"].options == 0  # laspy would write its own (wrong) min/max
    assert records["plane_p"].description == b"p-value of chi-square plane test"


def test_shorten_keeps_whole_words_within_32_ascii_bytes():
    assert shorten("distance to the estimated end of the visible surface") == (
        "distance to estimated end")
    assert shorten("nearest border: 1 scan window, 2 no return, 3 depth jump") == (
        "nearest border: 1 scan window")
    assert shorten("mean curvature (H<0 convex) of the fitted quadric") == (
        "mean curvature of fitted quadric")
    assert shorten("p-value of the consistent-curvature test") == (
        "p-value of consistent-curvature")
    assert shorten("x" * 40) == "x" * 32
    assert shorten("angle \u03b8 of the normal") == "angle ? of the normal"
    assert len(field_description("b" * 32)) <= 32


def test_chunked_write_is_the_file_laspy_writes_at_once(tmp_path, rng, monkeypatch):
    """A write packs WRITE_CHUNK points at a time; the bytes are those of one LasData.write."""
    from lidarstat.io import _las

    monkeypatch.setattr(_las, "WRITE_CHUNK", 37)  # several chunks and a short last one
    cloud = lio.PointCloud(rng.random((N, 3)) * 10 + 5e5)
    fields = _fields(rng)
    for suffix in (".las", ".laz"):
        out = tmp_path / f"o{suffix}"
        lio.write(out, cloud, fields=fields)
        header, assign = _las._header_for(out, cloud, fields)
        header.point_count = N
        rec = _las._record(out, header, cloud, assign)
        ref = tmp_path / f"ref{suffix}"
        with open(ref, "wb") as fh:
            laspy.LasData(header, points=rec).write(fh, do_compress=suffix == ".laz",
                                                     laz_backend=_las._BACKEND)
        assert out.read_bytes() == ref.read_bytes()
        _check(out, fields)


def test_a_failed_chunk_write_fails_the_write_and_leaves_no_file(tmp_path, rng, monkeypatch):
    """An error of one chunk's write reaches the caller as the write's error, later
    chunks are not written, no output remains."""
    from lidarstat.errors import PointCloudWriteError
    from lidarstat.io import _las

    monkeypatch.setattr(_las, "WRITE_CHUNK", 37)
    written = []
    real = laspy.LasWriter.write_points

    def write_points(self, points):
        if len(written) == 2:
            raise RuntimeError("disk gone")
        written.append(len(points))
        real(self, points)

    monkeypatch.setattr(laspy.LasWriter, "write_points", write_points)
    out = tmp_path / "o.las"
    with pytest.raises(PointCloudWriteError, match="disk gone"):
        lio.write(out, lio.PointCloud(rng.random((N, 3)) * 10 + 5e5), fields=_fields(rng))
    assert written == [37, 37] and not out.exists() and not list(tmp_path.iterdir())


def test_rewrite_copies_the_records_as_read(tmp_path, rng):
    """The input's records reach the output byte for byte (bit fields, an extra-bytes
    field of its own, the stored integer coordinates), with the new fields written over
    the standard `classification` and appended as extra bytes; `decode=False` gives
    the same file without decoding the chunks."""
    src = tmp_path / "src.las"
    header = laspy.LasHeader(version="1.2", point_format=3)
    header.add_extra_dims([laspy.ExtraBytesParams(name="theirs", type="u2")])
    header.scales, header.offsets = np.full(3, 0.01), np.array([5e5, 6e6, 0.0])
    las = laspy.LasData(header)
    las.x, las.y = 5e5 + rng.random(N) * 50, 6e6 + rng.random(N) * 50
    las.z = rng.random(N) * 9
    for name, hi in (("intensity", 65535), ("return_number", 7), ("number_of_returns", 7),
                     ("scan_direction_flag", 1), ("edge_of_flight_line", 1),
                     ("classification", 31), ("synthetic", 1), ("scan_angle_rank", 90),
                     ("user_data", 255), ("point_source_id", 65535), ("red", 65535),
                     ("theirs", 65535)):
        las[name] = rng.integers(0, hi + 1, N)
    las.gps_time = rng.random(N) * 1e5
    las.write(src)
    fields = {"classification": rng.integers(0, 32, N).astype(np.uint8),
              "cluster_id": np.arange(N, dtype=np.int32), "ground": rng.random(N) < 0.5}
    seen = []

    def fields_of(start, chunk):
        seen.append(chunk)
        return {k: v[start:start + len(chunk)] for k, v in fields.items()}

    outs = []
    for decode in (True, False):
        outs.append(tmp_path / f"o{decode}.las")
        lio.rewrite(src, outs[-1], fields_of, points_per_chunk=50, decode=decode)
    assert outs[0].read_bytes() == outs[1].read_bytes()
    assert isinstance(seen[0], lio.PointCloud) and seen[-1] == range(100, N)
    # the chunks after the first (the last one shorter) refill the first one's record:
    # the same bytes as one chunk in a new record
    whole = tmp_path / "whole.las"
    lio.rewrite(src, whole, fields_of, points_per_chunk=N, decode=False)
    assert whole.read_bytes() == outs[1].read_bytes()
    a, b = laspy.read(src), laspy.read(outs[1])
    for name in a.point_format.dimension_names:
        want = fields.get(name, a[name])
        np.testing.assert_array_equal(np.asarray(b[name]), np.asarray(want), err_msg=name)
    np.testing.assert_array_equal(np.asarray(b["cluster_id"]), fields["cluster_id"])
    np.testing.assert_array_equal(np.asarray(b["ground"]), fields["ground"])


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_rewrite_packs_write_chunks_inside_a_read_chunk(tmp_path, rng, monkeypatch, suffix):
    """Each read chunk is copied, filled and written WRITE_CHUNK points at a time: the
    file (points, header statistics, return counts) is the one of a single record."""
    from lidarstat.io import _las

    src = tmp_path / "src.las"
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.scales, header.offsets = np.full(3, 0.001), np.array([5e5, 6e6, 0.0])
    las = laspy.LasData(header)
    las.x, las.y = 5e5 + rng.random(N) * 50, 6e6 + rng.random(N) * 50
    las.z = rng.random(N) * 9 - 3
    las.number_of_returns = rng.integers(1, 6, N)
    las.return_number = rng.integers(1, 6, N)
    las.gps_time = rng.random(N) * 1e5
    las.write(src)
    fields = {"classification": rng.integers(0, 32, N).astype(np.uint8),
              "height": rng.normal(size=N), "cluster_id": np.arange(N, dtype=np.int32)}

    def fields_of(start, chunk):
        return {k: v[start:start + len(chunk)] for k, v in fields.items()}

    written = []
    real = laspy.LasWriter.write_points

    def write_points(self, points):
        written[-1].append(len(points))
        real(self, points)

    monkeypatch.setattr(laspy.LasWriter, "write_points", write_points)
    outs = []
    for write_chunk, read_chunk in ((N, N), (7, 50), (50, 7)):
        monkeypatch.setattr(_las, "WRITE_CHUNK", write_chunk)
        outs.append(tmp_path / f"o{write_chunk}{suffix}")
        written.append([])
        lio.rewrite(src, outs[-1], fields_of, points_per_chunk=read_chunk, decode=False)
    assert written[0] == [N] and written[2] == [7] * (N // 7) + [N % 7]
    assert written[1] == ([7] * 7 + [1]) * 2 + [7] * 2 + [6]  # 50, 50 and 20 points read
    assert outs[0].read_bytes() == outs[1].read_bytes() == outs[2].read_bytes()
    out = laspy.read(outs[1])
    assert list(out.header.number_of_points_by_return[:5]) == [
        int(np.sum(las.return_number == r)) for r in range(1, 6)]
    np.testing.assert_array_equal(out.header.maxs, las.xyz.max(axis=0))
    np.testing.assert_array_equal(np.asarray(out["height"]), fields["height"])
