"""Seed files and mutants for the readers' fuzz runs (see ``fuzz_support``).

Seeds: small valid files in every format at UTM-sized coordinates (LAS 1.2 and 1.4 with
VLRs, EVLRs and extra bytes, LAZ with fixed and variable chunks, binary and ASCII PLY, CSV,
TXT, NPZ, E57). Mutants: byte flips, truncations, junk, dropped or repeated ranges, LAS/LAZ
header fields overwritten at their offsets with boundary values, PLY header edits, bad text
cells, NPZ arrays of the wrong kind or with a forged shape, E57 XML values re-checksummed.
Everything is reproducible from one integer seed.
"""

from __future__ import annotations

import itertools
import math
import struct
from pathlib import Path

import numpy as np

_N_POINTS = 300

# --------------------------------------------------------------------------- seeds
def variable_chunk_laz(path: Path, xyz: np.ndarray, cuts=(0.3, 0.7)) -> Path:
    """A LAZ 1.2 (point format 3) with variable-size chunks split at the fractions `cuts`.

    laspy writes fixed-size chunks only: the file is laspy's, with the LasZip VLR swapped
    for a variable-chunk one of the same length and the points recompressed by lazrs.
    """
    import io

    import laspy
    import lazrs

    header = laspy.LasHeader(version="1.2", point_format=3)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(xyz.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    fixed = io.BytesIO()
    las.write(fixed, do_compress=True)
    data = fixed.getvalue()
    start = struct.unpack_from("<I", data, 96)[0]
    old = next(v for v in laspy.LasReader(io.BytesIO(data)).header.vlrs
               if v.record_id == 22204).record_data
    vlr = lazrs.LazVlr.new_for_compression(3, 0, True)
    at = data.index(bytes(old))
    out = io.BytesIO()
    out.write(data[:at] + bytes(vlr.record_data()) + data[at + len(old):start])
    raw, size = las.points.array.tobytes(), header.point_format.size
    edges = [0, *(int(c * len(xyz)) for c in cuts), len(xyz)]
    compressor = lazrs.LasZipCompressor(out, vlr)
    compressor.compress_chunks([raw[a * size:b * size] for a, b in itertools.pairwise(edges)])
    compressor.done()
    path.write_bytes(out.getvalue())
    return path


def make_seeds(folder: Path, rng: np.random.Generator) -> list[Path]:
    """Small valid files in every format, UTM-sized coordinates."""
    import laspy
    from laspy.vlrs.vlrlist import VLRList

    folder.mkdir(parents=True, exist_ok=True)
    n = _N_POINTS
    xyz = np.column_stack([431000 + rng.uniform(0, 50, n), 5_400_000 + rng.uniform(0, 50, n),
                           rng.uniform(-5, 40, n)])
    seeds = []
    for name, version, pf, extra, evlr in (("v12", "1.2", 3, False, False),
                                           ("v14", "1.4", 6, True, True),
                                           ("v14b", "1.4", 7, True, True),
                                           ("v10", "1.2", 1, False, False)):
        header = laspy.LasHeader(version=version, point_format=pf)
        header.scales = np.array([0.001, 0.001, 0.001])
        header.offsets = np.array([431000.0, 5_400_000.0, 0.0])
        header.vlrs.append(laspy.VLR(user_id="fuzz", record_id=1, description="seed",
                                     record_data=b"seed-vlr" * 3))
        if extra:
            header.add_extra_dims([laspy.ExtraBytesParams("H", "f8"),
                                   laspy.ExtraBytesParams("flag", "u1")])
        if evlr:
            header.evlrs = VLRList([laspy.VLR(user_id="fuzz", record_id=2,
                                              description="e", record_data=b"evlr" * 5)])
        las = laspy.LasData(header)
        las.x, las.y, las.z = xyz.T
        las.intensity = rng.integers(0, 65535, n)
        las.classification = rng.integers(0, 10, n)
        if extra:
            las.H = rng.normal(size=n)
            las.flag = rng.integers(0, 255, n)
        for suffix in (".las", ".laz"):
            if name in ("v10", "v14b") and suffix == ".las":
                continue
            path = folder / f"{name}{suffix}"
            las.write(path)
            seeds.append(path)
    seeds.append(variable_chunk_laz(folder / "var.laz", xyz))
    import plyfile

    arr = np.empty(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "u2")])
    arr["x"], arr["y"], arr["z"] = xyz.T
    arr["intensity"] = rng.integers(0, 65535, n)
    for text, name in ((False, "bin.ply"), (True, "asc.ply")):
        plyfile.PlyData([plyfile.PlyElement.describe(arr[:60] if text else arr, "vertex")],
                        text=text).write(str(folder / name))
        seeds.append(folder / name)
    lines = ["x,y,z,intensity"] + [f"{a},{b},{c},{i}" for (a, b, c), i in
                                   zip(xyz[:80].tolist(), arr["intensity"][:80].tolist())]
    (folder / "pts.csv").write_text("\n".join(lines) + "\n")
    (folder / "pts.txt").write_text("\n".join(ln.replace(",", " ") for ln in lines[1:40]) + "\n")
    np.savez(folder / "pts.npz", xyz=xyz, intensity=arr["intensity"])
    seeds += [folder / "pts.csv", folder / "pts.txt", folder / "pts.npz"]
    try:
        import pye57
    except ImportError:  # pragma: no cover - pye57 is a test dependency
        return seeds
    e57 = pye57.E57(str(folder / "scan.e57"), mode="w")
    e57.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1],
                        "cartesianZ": xyz[:, 2], "intensity": rng.uniform(0, 1, n)})
    e57.close()
    return [*seeds, folder / "scan.e57"]


# --------------------------------------------------------------------------- mutants
def _las_fields(data: bytes) -> list[tuple[int, str]]:
    """(offset, struct code) of the LAS/LAZ header fields worth overwriting."""
    fields = [(94, "H"), (96, "I"), (100, "I"), (104, "B"), (105, "H"), (107, "I"),
              (131, "d"), (139, "d"), (147, "d"), (155, "d"), (163, "d"), (171, "d")]
    if len(data) < 227:
        return fields
    minor, header_size, offset, n_vlrs = data[25], *struct.unpack_from("<HII", data, 94)
    if minor >= 4:
        fields += [(235, "Q"), (243, "I"), (247, "Q")]
    pos = header_size
    for _ in range(min(n_vlrs, 8)):  # record lengths of the VLRs
        if pos + 54 > min(offset, len(data)):
            break
        fields.append((pos + 20, "H"))
        user = data[pos + 2:pos + 18].rstrip(b"\0")
        if user == b"laszip encoded":  # chunk size and item sizes
            fields += [(pos + 54 + 12, "I"), (pos + 54 + 32, "H")]
            fields += [(pos + 54 + 34 + 6 * i + 2, "H") for i in range(3)]
        pos += 54 + struct.unpack_from("<H", data, pos + 20)[0]
    if data[104] & 0x80 and offset + 8 <= len(data):
        fields.append((offset, "q"))
        table = struct.unpack_from("<q", data, offset)[0]
        if 0 < table <= len(data) - 8:
            fields += [(table, "I"), (table + 4, "I")]
    return fields


def _interesting(code: str, old, rng: np.random.Generator):
    if code == "d":
        return rng.choice([0.0, -0.0, math.nan, math.inf, -math.inf, 1e306, 1e-306, 1e15,
                           -1.0, old * 1e6, old * -1, 5e-324])
    bits = struct.calcsize("<" + code) * 8
    signed = code in "bhiq"
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2 ** bits - 1)
    pick = rng.choice([lo, hi, hi // 2 + 1, 0, 1, old + 1, old - 1, old * 2, old // 2,
                       old * 1000, int(rng.integers(0, 2 ** min(bits, 62)))])
    return int(min(max(int(pick), lo), hi))


def _generic(data: bytes, rng: np.random.Generator) -> bytes:
    b = bytearray(data)
    kind = rng.integers(0, 5)
    if kind == 0 and len(b):  # flip a few bytes, biased towards the header
        for _ in range(rng.integers(1, 9)):
            i = int(rng.integers(0, min(len(b), 512) if rng.random() < 0.7 else len(b)))
            b[i] = int(rng.integers(0, 256))
    elif kind == 1:  # truncate
        b = b[: int(rng.integers(0, len(b) + 1))]
    elif kind == 2:  # append junk
        b += bytes(rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8))
    elif kind == 3 and len(b) > 8:  # zero a range
        i = int(rng.integers(0, len(b) - 1))
        m = min(int(rng.integers(1, 65)), len(b) - i)
        b[i: i + m] = bytes(m)
    else:  # duplicate or drop a range
        i, j = sorted(int(v) for v in rng.integers(0, len(b) + 1, 2))
        b = b[:j] + b[i:] if rng.random() < 0.5 else b[:i] + b[j:]
    return bytes(b)


def _mutate_las(data: bytes, rng) -> bytes:
    if rng.random() < 0.35:
        return _generic(data, rng)
    b = bytearray(data)
    fields = _las_fields(data)
    for _ in range(1 if rng.random() < 0.8 else 2):
        off, code = fields[int(rng.integers(0, len(fields)))]
        if off + struct.calcsize("<" + code) > len(b):
            continue
        old = struct.unpack_from("<" + code, b, off)[0]
        struct.pack_into("<" + code, b, off, _interesting(code, old, rng))
    return bytes(b)


_PLY_SWAPS = [(b"element vertex ", lambda m, r: str(int(m) * int(r.choice([0, 2, 1000, 10**12])))),
              (b"property double x", "property list uchar double x"),
              (b"property double y", "property char y"),
              (b"property ushort intensity", "property list int int intensity"),
              (b"format binary_little_endian", "format ascii"),
              (b"format ascii", "format binary_big_endian"),
              (b"end_header", "end_headr")]


def _mutate_ply(data: bytes, rng) -> bytes:
    if rng.random() < 0.5:
        return _generic(data, rng)
    key, repl = _PLY_SWAPS[int(rng.integers(0, len(_PLY_SWAPS)))]
    i = data.find(key)
    if i < 0:
        return _generic(data, rng)
    if callable(repl):
        j = data.index(b"\n", i)
        return data[: i + len(key)] + repl(data[i + len(key): j], rng).encode() + data[j:]
    return data[:i] + repl.encode() + data[i + len(key):]


_TOKENS = ["nan", "inf", "-inf", "1.5e308", "-1.5e308", "1e999", "abc", "", "1,2", "0x10",
           "1e15", "9" * 400, "\x00", "\ufeff", "'1'"]


def _mutate_text(data: bytes, rng) -> bytes:
    if rng.random() < 0.3:
        return _generic(data, rng)
    lines = data.decode("utf-8", "replace").split("\n")
    sep = "," if "," in lines[0] else " "
    for _ in range(int(rng.integers(1, 4))):
        i = int(rng.integers(0, max(len(lines) - 1, 1)))
        cells = lines[i].split(sep)
        kind = rng.integers(0, 3)
        if kind == 0 and cells:
            cells[int(rng.integers(0, len(cells)))] = str(rng.choice(_TOKENS))
        elif kind == 1:
            cells = cells[: int(rng.integers(0, len(cells) + 1))]
        else:
            cells.append(str(rng.choice(_TOKENS)))
        lines[i] = sep.join(cells)
    return "\n".join(lines).encode("utf-8", "surrogatepass")


def _mutate_npz(path: Path, data: bytes, rng) -> bytes:
    kind = rng.integers(0, 3)
    if kind == 0:
        return _generic(data, rng)
    n = _N_POINTS
    xyz = np.column_stack([431000 + np.arange(n) * 0.1, np.full(n, 5.4e6), np.zeros(n)])
    choices = [lambda: {"xyz": xyz.astype(str)}, lambda: {"xyz": xyz[:, :2]},
               lambda: {"xyz": xyz[None]}, lambda: {"xyz": np.array(1.0)},
               lambda: {"x": xyz[:, 0], "y": xyz[:5, 1], "z": xyz[:, 2]},
               lambda: {"x": xyz[:, 0].astype(str), "y": xyz[:, 1], "z": xyz[:, 2]},
               lambda: {"xyz": np.where(np.arange(n)[:, None] % 7 == 0, 1.5e308, xyz)},
               lambda: {"xyz": np.where(np.arange(n)[:, None] % 5 == 0, np.nan, xyz)},
               lambda: {"xyz": xyz, "intensity": np.arange(n + 1)},
               lambda: {"xyz": np.empty((0, 3))}, lambda: {"other": xyz},
               lambda: {"xyz": xyz.astype(complex)},
               lambda: {"xyz": np.array([[object(), 1, 2]] * 3, dtype=object)}]
    if kind == 1:
        import io

        buf = io.BytesIO()
        np.savez(buf, allow_pickle=True, **choices[int(rng.integers(0, len(choices)))]())
        return buf.getvalue()
    # kind 2: overwrite the shape in a stored .npy header, keeping its length
    b = bytearray(data)
    i = b.find(b"'shape': (")
    if i < 0:
        return _generic(data, rng)
    j = b.index(b")", i)
    shape = str(rng.choice(["(10000000000000, 3", "(300, 3, 9", "(3000, 3", "(-1, 3", "(",
                            "(300,", "(9999999999999999999999, 3"])).encode()
    new = b"'shape': " + shape
    pad = (j - i) - len(new)
    if pad < 0:
        return _generic(data, rng)
    b[i:j] = new + b" " * pad  # padding before ')' keeps the header parseable or not
    return bytes(b)


_CRC_TABLE: list[int] = []


def _crc32c(data: bytes) -> int:
    if not _CRC_TABLE:
        for i in range(256):
            c = i
            for _ in range(8):
                c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
            _CRC_TABLE.append(c)
    c = 0xFFFFFFFF
    for x in data:
        c = _CRC_TABLE[(c ^ x) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


_E57_VALUES = ["0", "-1", "1", "300000000000", "9223372036854775807", "-9223372036854775808",
               "1e308", "nan", "abc", "", "4294967296", "48", "999999"]


def rewrite_e57_xml(data: bytes, edit) -> bytes:
    """E57 file `data` with its XML section replaced by ``edit(xml)``, pages re-checksummed.

    The XML section is the last one of files written by pye57; the header's physical length
    and XML length follow the new text.
    """
    page = 1024
    _, _, _, _, xml_at, xml_len, _ = struct.unpack_from("<8sIIQQQQ", data, 0)
    logical = bytearray(b"".join(data[p:p + page - 4] for p in range(0, len(data), page)))
    start = xml_at // page * (page - 4) + xml_at % page
    xml = edit(logical[start:start + xml_len].decode("utf-8", "replace")).encode()
    new = logical[:start] + xml
    new += bytes(-len(new) % (page - 4))
    struct.pack_into("<QQQ", new, 16, len(new) // (page - 4) * page, xml_at, len(xml))
    out = bytearray()
    for p in range(0, len(new), page - 4):
        chunk = bytes(new[p:p + page - 4])
        out += chunk + _crc32c(chunk).to_bytes(4, "big")
    return bytes(out)


def _mutate_e57(data: bytes, rng) -> bytes:
    """Change one or two values of the XML section, with valid page checksums (a byte flip
    alone only fails the checksum of its page)."""
    if rng.random() < 0.2:
        return _generic(data, rng)
    import re

    value = re.compile(r'(?:="|>)([^"<>]*)(?:"|</)')

    def edit(xml: str) -> str:
        for _ in range(int(rng.integers(1, 3))):
            spots = [m.span(1) for m in value.finditer(xml)]
            a, b = spots[int(rng.integers(0, len(spots)))]
            xml = xml[:a] + str(rng.choice(_E57_VALUES)) + xml[b:]
        return xml

    return rewrite_e57_xml(data, edit)


def make_mutants(seeds: list[Path], folder: Path, count: int, seed: int) -> list[Path]:
    """`count` mutants of the seeds (round robin), reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    blobs = {p: p.read_bytes() for p in seeds}
    out = []
    for k in range(count):
        src = seeds[k % len(seeds)]
        data, suffix = blobs[src], src.suffix
        if suffix in (".las", ".laz"):
            new = _mutate_las(data, rng)
        elif suffix == ".ply":
            new = _mutate_ply(data, rng)
        elif suffix == ".npz":
            new = _mutate_npz(src, data, rng)
        elif suffix == ".e57":
            new = _mutate_e57(data, rng)
        else:
            new = _mutate_text(data, rng)
        path = folder / f"m{k:05d}_{src.stem}{suffix}"
        path.write_bytes(new)
        out.append(path)
    return out
