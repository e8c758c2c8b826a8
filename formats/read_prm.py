#!/usr/bin/env python3
"""Independent reader of .prm archives (format 2.1), written from formats/prm.md.

Usage: read_prm.py [--pane N] [--no-verify] ARCHIVE

Parses and validates ARCHIVE and prints a JSON summary on stdout. With
--pane N, pane N is decoded from its tiles' bases by the rule of section 7.2
(binary32 products and sums in order, emulated in Python's binary64) and its
texels, energy and peak are included. Checksums are verified unless
--no-verify is given (the pure-Python XXH3 used when the `xxhash` module is
missing is slow on large archives). A format 1 archive is refused: it must be
baked again.

Needs only the Python 3 standard library plus a zstd decoder: the
`zstandard` module if importable, otherwise the `zstd` command-line tool.

Exit status: 0 success, 1 invalid archive, 2 usage error,
3 no zstd decoder available.
"""

import json
import shutil
import struct
import subprocess
import sys

MAGIC = b"\x89PRM\r\n\x1a\n"
SUPPORTED_MAJOR = 2
SUPPORTED_MINOR = 1
KINDS = {1: "metadata", 2: "atlas", 3: "entries", 4: "clusters", 5: "panes", 6: "entry_energy",
         7: "emitters", 8: "sky", 9: "probes", 10: "probe_rays",
         11: "near_field", 12: "entry_cells"}
OPTIONAL = {6, 7, 8, 9, 10, 11, 12}
RAY_SKY = 0xFFFFFFFF
RAY_BLOCKED = 0xFFFFFFFE
SH_COEFFS = 9
# The reader's limits (formats/prm.md), before any allocation.
MAX_PROBE_RAYS = MAX_NEAR_RAYS = MAX_PROBES = MAX_SECTIONS = 1 << 16
MAX_PROBE_CELLS = MAX_TRIANGLES = MAX_ENTRIES = MAX_METADATA = 1 << 24
MAX_CLUSTERS = 1 << 20
MAX_EMITTER_GROUPS = 256
MAX_RESOLUTION = 8192
MAX_TILE_SIZE = 1024


class InvalidArchive(Exception):
    pass


class NoZstd(Exception):
    pass


# ----------------------------------------------------------------- XXH3-64
# Port of the scalar XXH3_64bits (seed 0, default secret), xxHash 0.8.

M64 = (1 << 64) - 1
P32_1, P32_2, P32_3 = 0x9E3779B1, 0x85EBCA77, 0xC2B2AE3D
P64_1, P64_2, P64_3 = 0x9E3779B185EBCA87, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9
P64_4, P64_5 = 0x85EBCA77C2B2AE63, 0x27D4EB2F165667C5
SECRET = bytes.fromhex(
    "b8fe6c3923a44bbe7c01812cf721ad1cded46de9839097db7240a4a4b7b3671f"
    "cb79e64eccc0e578825ad07dccff7221b8084674f743248ee03590e6813a264c"
    "3c2852bb91c300cb88d0658b1b532ea371644897a20df94e3819ef46a9deacd8"
    "a8fa763fe39c343ff9dcbbc7c70b4f1d8a51e04bcdb45931c89f7ec9d9787364"
    "eac5ac8334d3ebc3c581a0fffa1363eb170ddd51b7f0da49d316552629d4689e"
    "2b16be587d47a1fc8ff8b8d17ad031ce45cb3a8f95160428afd7fbcabb4b407e"
)


def _r64(b, o):
    return int.from_bytes(b[o:o + 8], "little")


def _r32(b, o):
    return int.from_bytes(b[o:o + 4], "little")


def _avalanche64(h):
    h ^= h >> 33
    h = (h * P64_2) & M64
    h ^= h >> 29
    h = (h * P64_3) & M64
    return h ^ (h >> 32)


def _avalanche3(h):
    h ^= h >> 37
    h = (h * 0x165667919E3779F9) & M64
    return h ^ (h >> 32)


def _rotl(v, r):
    return ((v << r) | (v >> (64 - r))) & M64


def _fold(a, b):
    p = a * b
    return (p & M64) ^ (p >> 64)


def _mix16(b, o, so):
    lo = _r64(b, o) ^ _r64(SECRET, so)
    hi = _r64(b, o + 8) ^ _r64(SECRET, so + 8)
    return _fold(lo, hi)


def xxh3_64_pure(b):
    n = len(b)
    if n == 0:
        return _avalanche64(_r64(SECRET, 56) ^ _r64(SECRET, 64))
    if n <= 3:
        combo = (b[0] << 16) | (b[n >> 1] << 24) | b[n - 1] | (n << 8)
        return _avalanche64(combo ^ (_r32(SECRET, 0) ^ _r32(SECRET, 4)))
    if n <= 8:
        flip = _r64(SECRET, 8) ^ _r64(SECRET, 16)
        keyed = ((_r32(b, n - 4) + (_r32(b, 0) << 32)) & M64) ^ flip
        h = keyed ^ _rotl(keyed, 49) ^ _rotl(keyed, 24)
        h = (h * 0x9FB21C651E98DF25) & M64
        h ^= (h >> 35) + n
        h = (h * 0x9FB21C651E98DF25) & M64
        return h ^ (h >> 28)
    if n <= 16:
        lo = _r64(b, 0) ^ (_r64(SECRET, 24) ^ _r64(SECRET, 32))
        hi = _r64(b, n - 8) ^ (_r64(SECRET, 40) ^ _r64(SECRET, 48))
        swapped = int.from_bytes(lo.to_bytes(8, "little"), "big")
        return _avalanche3((n + swapped + hi + _fold(lo, hi)) & M64)
    if n <= 128:
        acc = (n * P64_1) & M64
        if n > 32:
            if n > 64:
                if n > 96:
                    acc += _mix16(b, 48, 96) + _mix16(b, n - 64, 112)
                acc += _mix16(b, 32, 64) + _mix16(b, n - 48, 80)
            acc += _mix16(b, 16, 32) + _mix16(b, n - 32, 48)
        acc += _mix16(b, 0, 0) + _mix16(b, n - 16, 16)
        return _avalanche3(acc & M64)
    if n <= 240:
        acc = (n * P64_1) & M64
        for i in range(8):
            acc += _mix16(b, 16 * i, 16 * i)
        acc = _avalanche3(acc & M64)
        for i in range(8, n // 16):
            acc += _mix16(b, 16 * i, 16 * (i - 8) + 3)
        acc += _mix16(b, n - 16, 136 - 17)
        return _avalanche3(acc & M64)
    # long input: stripes of 64 bytes, 8 accumulators
    acc = [P32_3, P64_1, P64_2, P64_3, P64_4, P32_2, P64_5, P32_1]
    skeys = [[_r64(SECRET, 8 * s + 8 * i) for i in range(8)] for s in range(16)]

    def accumulate(off, keys):
        words = struct.unpack_from("<8Q", b, off)
        for i in range(8):
            v = words[i]
            k = v ^ keys[i]
            acc[i ^ 1] = (acc[i ^ 1] + v) & M64
            acc[i] = (acc[i] + (k & 0xFFFFFFFF) * (k >> 32)) & M64

    stripes_per_block = (len(SECRET) - 64) // 8  # 16
    block_len = 64 * stripes_per_block
    nb_blocks = (n - 1) // block_len
    scramble = [_r64(SECRET, len(SECRET) - 64 + 8 * i) for i in range(8)]
    for blk in range(nb_blocks):
        for s in range(stripes_per_block):
            accumulate(blk * block_len + s * 64, skeys[s])
        for i in range(8):
            a = acc[i]
            a ^= a >> 47
            a ^= scramble[i]
            acc[i] = (a * P32_1) & M64
    for s in range(((n - 1) - block_len * nb_blocks) // 64):
        accumulate(nb_blocks * block_len + s * 64, skeys[s])
    accumulate(n - 64, [_r64(SECRET, len(SECRET) - 64 - 7 + 8 * i) for i in range(8)])
    result = (n * P64_1) & M64
    for i in range(4):
        result += _fold(acc[2 * i] ^ _r64(SECRET, 11 + 16 * i), acc[2 * i + 1] ^ _r64(SECRET, 11 + 16 * i + 8))
    return _avalanche3(result & M64)


try:
    import xxhash as _xxhash

    def xxh3_64(b):
        return _xxhash.xxh3_64_intdigest(b)
except ImportError:
    xxh3_64 = xxh3_64_pure


# -------------------------------------------------------------------- zstd

try:
    import zstandard as _zstandard
except ImportError:
    _zstandard = None


def zstd_decompress(data, raw_size, what):
    """Decompresses a zstd stream that must produce exactly raw_size bytes."""
    limit = raw_size + 1
    if _zstandard is not None:
        out = bytearray()
        try:
            reader = _zstandard.ZstdDecompressor().stream_reader(data, read_across_frames=True)
            while len(out) < limit:
                chunk = reader.read(min(1 << 20, limit - len(out)))
                if not chunk:
                    break
                out += chunk
        except _zstandard.ZstdError as e:
            raise InvalidArchive(f"cannot decompress {what}: {e}")
    else:
        exe = shutil.which("zstd")
        if exe is None:
            raise NoZstd("neither the python 'zstandard' module nor the 'zstd' command is available")
        p = subprocess.run([exe, "-d", "-c", "-q"], input=data, capture_output=True)
        if p.returncode != 0:
            raise InvalidArchive(f"cannot decompress {what}: {p.stderr.decode(errors='replace').strip()}")
        out = p.stdout
    if len(out) != raw_size:
        raise InvalidArchive(f"{what} decompressed to {len(out)} bytes, expected {raw_size}")
    return bytes(out)


# ------------------------------------------------------------------ RGB9E5

def unplane(b, w, raw=False):
    """Values of w bytes stored in w byte planes (section 1): as little-endian integers, or with
    raw=True as their bytes in order."""
    n = len(b) // w
    out = bytearray(n * w)
    for plane in range(w):
        out[plane::w] = b[plane * n:(plane + 1) * n]
    if raw:
        return out
    return struct.unpack(f"<{n}I", out) if w == 4 else out


def decode_rgb9e5(t):
    scale = 2.0 ** ((t >> 27) - 24)
    return [(t & 0x1FF) * scale, ((t >> 9) & 0x1FF) * scale, ((t >> 18) & 0x1FF) * scale]


_F32 = struct.Struct("<f")


def to_f32(x):
    """x rounded to the nearest binary32 (an overflow gives the infinity of its sign)."""
    try:
        return _F32.unpack(_F32.pack(x))[0]
    except OverflowError:
        return float("inf") if x > 0 else float("-inf")


def decode_value(u, c):
    """The spec's decoded value (section 7.2): v = 0, then v = f32(v + f32(u[k] * c[k])) for
    k = 0, 1, ...; then v if v > 0 else +0. A binary32 product or sum computed in binary64 and
    rounded once more to binary32 is the correctly rounded binary32 result (53 >= 2*24 + 2)."""
    v = 0.0
    for x, y in zip(u, c):
        v = to_f32(v + to_f32(x * y))
    return v if v > 0 else 0.0


# ------------------------------------------------------------------ reader

def gather_points(section, raw, at, count, texels, groups):
    """The `count` gather-point records of the near field or the probe rays from byte `at` of
    `raw` (texel u32, position, normal, albedo, emission 3 f32 each, emitter group u32 or
    0xFFFFFFFF), each checked: a texel of the atlas, finite values, albedo and emission not
    negative, an emitter group that exists."""
    points = []
    for i in range(count):
        rec = struct.unpack_from("<I12fI", raw, at + 56 * i)
        if rec[0] >= texels or any(v != v or abs(v) == float("inf") for v in rec[1:13]) or min(rec[7:13]) < 0:
            raise InvalidArchive(f"{section}: gather point outside the atlas or not finite")
        if rec[13] != 0xFFFFFFFF and rec[13] >= groups:
            raise InvalidArchive(f"{section}: gather point of an emitter group that does not exist")
        points.append(dict(texel=rec[0], position=list(rec[1:4]), normal=list(rec[4:7]), albedo=list(rec[7:10]),
                           emission=list(rec[10:13]), emitter=rec[13]))
    return points


class Reader:
    def __init__(self, data, verify=True):
        self.d = data
        self.verify = verify
        self.checksums_verified = verify

    def check(self, data, expected, what):
        if self.verify and xxh3_64(data) != expected:
            raise InvalidArchive(f"checksum mismatch in {what}")

    def parse(self):
        d = self.d
        n = len(d)
        if d[:8] != MAGIC[:min(8, n)]:
            raise InvalidArchive("bad magic")
        if n < 64:
            raise InvalidArchive("truncated: shorter than the header")
        major, minor = struct.unpack_from("<HH", d, 8)
        if major == 1:
            raise InvalidArchive(f"this archive is .prm format {major}.{minor}, and this reader reads "
                                 f"format {SUPPORTED_MAJOR}.x only: re-bake the scene with a prm-bake "
                                 f"that writes format {SUPPORTED_MAJOR}")
        if major != SUPPORTED_MAJOR:
            raise InvalidArchive(f"unsupported version {major}.{minor}")
        (count, table_off, file_len, res0, res1, table_sum, head_sum) = struct.unpack_from("<IQQQQQQ", d, 12)
        self.check(d[:56], head_sum, "header")
        strict = minor <= SUPPORTED_MINOR
        if file_len > n:
            raise InvalidArchive(f"truncated: header declares {file_len} bytes, file has {n}")
        if file_len < n:
            raise InvalidArchive("trailing bytes after the archive")
        if strict and (res0 or res1):
            raise InvalidArchive("reserved header fields not zero")
        if count > MAX_SECTIONS or table_off < 64 or table_off + 48 * count > n:
            raise InvalidArchive("section table outside the file")
        table = d[table_off:table_off + 48 * count]
        self.check(table, table_sum, "section table")
        sections = []
        spans = [(table_off, table_off + 48 * count)]
        for i in range(count):
            kind, comp, off, stored, raw, csum, reserved = struct.unpack_from("<IIQQQQQ", table, 48 * i)
            if kind == 0:
                raise InvalidArchive("section kind 0")
            if strict and reserved:
                raise InvalidArchive("reserved section field not zero")
            if off < 64 or off + stored > n:
                raise InvalidArchive(f"section {kind} outside the file")
            spans.append((off, off + stored))
            sections.append(dict(kind=kind, name=KINDS.get(kind, f"unknown (kind {kind})"),
                                 compression=comp, offset=off, stored_size=stored,
                                 raw_size=raw, checksum=f"{csum:016x}", _sum=csum))
        spans.sort()
        for a, b in zip(spans, spans[1:]):
            if a[1] > b[0]:
                raise InvalidArchive("overlapping sections")
        by_kind = {}
        for s in sections:
            if s["kind"] in KINDS:
                if s["kind"] in by_kind:
                    raise InvalidArchive(f"duplicate {s['name']} section")
                by_kind[s["kind"]] = s
            elif self.verify:
                # unknown kinds are skipped, but their stored bytes are checked
                self.check(d[s["offset"]:s["offset"] + s["stored_size"]], s["_sum"], s["name"])
        for k, name in KINDS.items():
            if k not in by_kind and k not in OPTIONAL:
                raise InvalidArchive(f"missing {name} section")
        self.version = f"{major}.{minor}"
        self.minor = minor
        self.file_length = n
        self.sections = sections
        self.strict = strict

        max_raw = {1: MAX_METADATA, 2: 16 + 24 * MAX_TRIANGLES + (MAX_RESOLUTION ** 2 + 7) // 8,
                   3: 28 * MAX_ENTRIES, 4: 56 * MAX_CLUSTERS}
        raw = {k: self.load(by_kind[k], max_raw[k]) for k in (1, 2, 3, 4)}

        try:
            meta = json.loads(raw[1].decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as e:
            raise InvalidArchive(f"metadata is not JSON: {e}")
        if not isinstance(meta, dict) or meta.get("texel_encoding") != "rgb9e5ufloat":
            raise InvalidArchive("metadata: texel_encoding must be rgb9e5ufloat")
        fp = meta.get("scene_fingerprint")
        if not (isinstance(fp, str) and len(fp) == 16 and all(c in "0123456789abcdefABCDEF" for c in fp)):
            raise InvalidArchive("metadata: scene_fingerprint must be 16 hex digits")
        self.accuracy = self.parse_accuracy(meta.get("accuracy"))
        self.metadata = meta

        self.parse_atlas(raw[2])
        self.parse_entries_clusters(raw[3], raw[4])
        self.entry_energy = None
        if 6 in by_kind:
            # One RGB f32 record per entry, finite and >= 0.
            er = self.load(by_kind[6], 12 * len(self.entries))
            if len(er) != 12 * len(self.entries):
                raise InvalidArchive("entry_energy: not one record per entry")
            vals = [list(struct.unpack_from("<3f", er, 12 * i)) for i in range(len(self.entries))]
            if any(v != v or v < 0 or v == float("inf") for r in vals for v in r):
                raise InvalidArchive("entry_energy: values must be finite and non-negative")
            self.entry_energy = vals
        self.emitters = None
        if 7 in by_kind:
            self.parse_emitters(by_kind[7])
        self.sky = None
        if 8 in by_kind:
            self.parse_sky(by_kind[8])
        self.probes = None
        if 9 in by_kind:
            self.parse_probes(by_kind[9])
        self.probe_rays = None
        if 10 in by_kind:
            if self.probes is None:
                raise InvalidArchive("probe_rays: no probes section")
            self.parse_probe_rays(by_kind[10])
        self.near_field = None
        if 11 in by_kind:
            self.parse_near_field(by_kind[11])
        self.entry_cells = None
        if 12 in by_kind:
            self.parse_entry_cells(by_kind[12])
        self.parse_panes(by_kind[5])

    def parse_entry_cells(self, s):
        # 16-byte header (entries N, points M, two reserved words 0), N ends (u32, entry i's
        # points are [end[i-1], end[i]), non-decreasing, the last M), then M points of 8 bytes:
        # the offset from the entry point as three f16, the unit normal octahedral in two u8.
        n_entries = len(self.entries)
        raw = self.load(s, 16 + 4 * n_entries + 8 * (1 << 32))
        if len(raw) < 16:
            raise InvalidArchive("entry_cells: shorter than its header")
        n, m, r0, r1 = struct.unpack_from("<4I", raw, 0)
        if n != n_entries or r0 or r1:
            raise InvalidArchive("entry_cells: not one cell per entry, or reserved words not 0")
        if len(raw) != 16 + 4 * n + 8 * m:
            raise InvalidArchive("entry_cells: raw size differs from what the header gives")
        ends = list(struct.unpack_from(f"<{n}I", raw, 16))
        if any(b < a for a, b in zip([0] + ends, ends)) or (ends[-1] if ends else 0) != m:
            raise InvalidArchive("entry_cells: ends out of order or not covering the points")
        points = []
        for i in range(m):
            x, y, z = struct.unpack_from("<3e", raw, 16 + 4 * n + 8 * i)
            u, v = struct.unpack_from("<2B", raw, 16 + 4 * n + 8 * i + 6)
            if not all(abs(c) != float("inf") and c == c for c in (x, y, z)):
                raise InvalidArchive("entry_cells: a point's offset is not finite")
            points.append(dict(offset=[x, y, z], octahedral=[u, v]))
        self.entry_cells = dict(ends=ends, points=points)

    def parse_near_field(self, s):
        # 32-byte header (exits E, rays per exit M, gather points G, flags (bit 0: the weights
        # complement the panes' kernel), atlas resolution, hits H, disk R^2 f32, the deeper VPLs'
        # disk R1^2 f32, 0 <= R1^2 <= R^2), G gather point records as in probe_rays,
        # E exit records (texel u32, end of its hits u32), then the H hits' gather point indices as
        # differences from the previous hit's (u32, mod 2^32, in 4 byte planes), then their H
        # distance codes (u8): r^2 = R^2 (1/w - 1), w = 1/16 + 15/16 q/255, all in binary32.
        texels = self.resolution * self.resolution
        groups = len(self.emitters or [])
        raw = self.load(s, 32 + (56 + 8) * texels + 5 * texels * MAX_NEAR_RAYS)
        if len(raw) < 32:
            raise InvalidArchive("near_field: shorter than its header")
        e, m, g, flags, res, h = struct.unpack_from("<6I", raw, 0)
        disk, indirect_disk = struct.unpack_from("<ff", raw, 24)
        if flags & ~1:
            raise InvalidArchive("near_field: unknown flags")
        if res != self.resolution or not 1 <= m <= MAX_NEAR_RAYS or g > texels or e > texels or h > e * m:
            raise InvalidArchive("near_field: resolution, ray, point, exit or hit count out of range")
        if not (disk > 0 and disk != float("inf")):
            raise InvalidArchive("near_field: disk not finite and positive")
        if not 0 <= indirect_disk <= disk:
            raise InvalidArchive("near_field: indirect disk not between 0 and the disk")
        if len(raw) != 32 + 56 * g + 8 * e + 5 * h:
            raise InvalidArchive("near_field: raw size differs from what the header gives")
        points = gather_points("near_field", raw, 32, g, texels, groups)
        at = 32 + 56 * g
        exits, last, end = [], -1, 0
        for i in range(e):
            texel, stop = struct.unpack_from("<2I", raw, at + 8 * i)
            if texel >= texels or texel <= last or stop <= end or stop > h or stop - end > m:
                raise InvalidArchive("near_field: exit records out of order or outside the hits")
            exits.append(dict(texel=texel, end=stop))
            last, end = texel, stop
        if end != h:
            raise InvalidArchive("near_field: the exits do not cover the hits")
        at += 8 * e
        hits, point = [], 0
        deltas = unplane(raw[at:at + 4 * h], 4)
        codes = raw[at + 4 * h:at + 5 * h]
        for i in range(h):
            point = (point + deltas[i]) & 0xFFFFFFFF
            w = to_f32(1 / 16 + to_f32(15 / 16 * to_f32(codes[i] / 255)))
            r2 = to_f32(disk * to_f32(to_f32(1 / w) - 1))
            if point >= g or r2 == float("inf"):
                raise InvalidArchive("near_field: a hit at a gather point that does not exist or not finite")
            hits.append(dict(point=point, distance2=r2))
        self.near_field = dict(rays_per_exit=m, disk=disk, indirect_disk=indirect_disk, complement=bool(flags & 1),
                               points=points, exits=exits, hits=hits)

    def parse_probe_rays(self, s):
        # 32-byte header (probes N, rays per probe M, gather points G, flags = 0, atlas
        # resolution, 3 reserved), G records (texel u32, position, normal, albedo, emission
        # 3 f32 each, emitter group u32), then N x M hits (u32): a gather point, RAY_SKY or
        # RAY_BLOCKED.
        n_probes = len(self.probes["cells"])
        texels = self.resolution * self.resolution
        groups = len(self.emitters or [])
        raw = self.load(s, 32 + 56 * texels + 4 * n_probes * MAX_PROBE_RAYS)
        if len(raw) < 32:
            raise InvalidArchive("probe_rays: shorter than its header")
        n, m, g, flags, res, r0, r1, r2 = struct.unpack_from("<8I", raw, 0)
        if flags or (self.strict and (r0 or r1 or r2)):
            raise InvalidArchive("probe_rays: unknown flags or a non-zero reserved field")
        if n != n_probes or res != self.resolution or not 1 <= m <= MAX_PROBE_RAYS or g > texels:
            raise InvalidArchive("probe_rays: probe count, resolution, ray count or point count out of range")
        if len(raw) != 32 + 56 * g + 4 * n * m:
            raise InvalidArchive("probe_rays: raw size differs from what the header gives")
        points = gather_points("probe_rays", raw, 32, g, texels, groups)
        hits = list(struct.unpack_from(f"<{n * m}I", raw, 32 + 56 * g))
        if any(h >= g and h not in (RAY_SKY, RAY_BLOCKED) for h in hits):
            raise InvalidArchive("probe_rays: a ray ends at a gather point that does not exist")
        self.probe_rays = dict(rays_per_probe=m, points=points, hits=hits)

    def parse_probes(self, s):
        # 48-byte header (probes N, clusters C, coefficient count = 9, flags (bit 0: sky),
        # grid nx ny nz, reserved, origin xyz, spacing), N records (cell u32, position 3 f32),
        # C x N transfers of 9 RGB binary16, cluster by cluster, then with the sky flag N sky
        # transfers of 9 x 9 RGB binary16.
        c_count = len(self.clusters)
        raw = self.load(s, 48 + (16 + 54 * c_count + 486) * MAX_PROBES)
        head = raw[:48]
        if len(head) < 48:
            raise InvalidArchive("probes: shorter than its header")
        n, c, coeffs, flags, nx, ny, nz, reserved = struct.unpack_from("<8I", head, 0)
        origin = list(struct.unpack_from("<3f", head, 32))
        spacing, = struct.unpack_from("<f", head, 44)
        if coeffs != SH_COEFFS or flags & ~1 or (self.strict and reserved):
            raise InvalidArchive("probes: unknown basis, flags or a non-zero reserved field")
        has_sky = bool(flags & 1)
        cells = nx * ny * nz
        if not 1 <= n <= MAX_PROBES or c != c_count or not 1 <= cells <= MAX_PROBE_CELLS or 0 in (nx, ny, nz):
            raise InvalidArchive("probes: probe count, cluster count or grid out of range")
        if not (spacing > 0 and spacing != float("inf")) or any(v != v or abs(v) == float("inf") for v in origin):
            raise InvalidArchive("probes: origin or spacing not finite and positive")
        size = 48 + 16 * n + 54 * n * c + (486 * n if has_sky else 0)
        if len(raw) != size:
            raise InvalidArchive("probes: raw size differs from what the header gives")
        recs = [struct.unpack_from("<I3f", raw, 48 + 16 * i) for i in range(n)]
        cell_list = [r[0] for r in recs]
        if any(a >= b for a, b in zip(cell_list, cell_list[1:])) or cell_list[-1] >= cells:
            raise InvalidArchive("probes: cells must increase strictly and lie in the grid")
        if any(v != v or abs(v) == float("inf") for r in recs for v in r[1:]):
            raise InvalidArchive("probes: positions must be finite")
        m = 27 * n * c
        t = struct.unpack_from(f"<{m}e", raw, 48 + 16 * n)
        sky = struct.unpack_from(f"<{243 * n}e", raw, 48 + 16 * n + 2 * m) if has_sky else ()
        if any(v != v or abs(v) == float("inf") for v in t + sky):
            raise InvalidArchive("probes: values must be finite")
        self.probes = dict(dims=[nx, ny, nz], origin=origin, spacing=spacing, cells=cell_list,
                           positions=[list(r[1:]) for r in recs],
                           transfer=[[list(t[27 * i + 3 * k:27 * i + 3 * k + 3]) for k in range(SH_COEFFS)]
                                     for i in range(n * c)],
                           sky=[[[list(sky[243 * p + 27 * i + 3 * k:243 * p + 27 * i + 3 * k + 3])
                                  for k in range(SH_COEFFS)] for i in range(SH_COEFFS)]
                                for p in range(n)] if has_sky else None)

    def parse_sky(self, s):
        # Header (resolution, coefficient count = 9, flags = 0, reserved), then per texel
        # 9 direct coefficients, then per texel 9 RGB indirect triples, all IEEE binary16.
        texels = self.resolution * self.resolution
        size = 16 + texels * SH_COEFFS * 8
        raw = self.load(s, size)
        if len(raw) < 16:
            raise InvalidArchive("sky: shorter than its header")
        res, coeffs, flags, reserved = struct.unpack_from("<IIII", raw, 0)
        if coeffs != SH_COEFFS or flags or (self.strict and reserved):
            raise InvalidArchive("sky: unknown basis, flags or a non-zero reserved field")
        if res != self.resolution or len(raw) != size:
            raise InvalidArchive("sky: resolution or raw size differs from the archive's")
        n = texels * SH_COEFFS
        direct = struct.unpack_from(f"<{n}e", raw, 16)
        indirect = struct.unpack_from(f"<{3 * n}e", raw, 16 + 2 * n)
        if any(v != v or abs(v) == float("inf") for v in direct + indirect):
            raise InvalidArchive("sky: values must be finite")
        self.sky = dict(direct=[list(direct[SH_COEFFS * t:SH_COEFFS * (t + 1)]) for t in range(texels)],
                        indirect=[[list(indirect[27 * t + 3 * c:27 * t + 3 * c + 3]) for c in range(SH_COEFFS)]
                                  for t in range(texels)])

    def parse_emitters(self, s):
        # Header (groups, entries, resolution, reserved), 88-byte group records, then per
        # group an RGB f32 triple per entry and two RGB9E5 words per atlas texel (direct, then
        # indirect: zeros unless flag bit 0 is set).
        n_entries, texels = len(self.entries), self.resolution * self.resolution
        limit = 16 + MAX_EMITTER_GROUPS * (88 + 12 * n_entries + 8 * texels)
        raw = self.load(s, limit)
        if len(raw) < 16:
            raise InvalidArchive("emitters: shorter than its header")
        groups, entries, res, reserved = struct.unpack_from("<IIII", raw, 0)
        if self.strict and reserved:
            raise InvalidArchive("emitters reserved field not zero")
        if not 1 <= groups <= MAX_EMITTER_GROUPS:
            raise InvalidArchive("emitters: group count outside 1..=256")
        if entries != n_entries or res != self.resolution:
            raise InvalidArchive("emitters: entry count or resolution differs from the archive's")
        size = 16 + groups * (88 + 12 * n_entries + 8 * texels)
        if len(raw) != size:
            raise InvalidArchive("emitters: raw size does not match its counts")
        out, at = [], 16 + 88 * groups
        for g in range(groups):
            rec = raw[16 + 88 * g:16 + 88 * (g + 1)]
            name = rec[:64]
            end = name.find(b"\0") if b"\0" in name else 64
            if any(name[end:]):
                raise InvalidArchive("emitters: bytes after a name's NUL padding")
            try:
                name = name[:end].decode("utf-8")
            except UnicodeDecodeError:
                raise InvalidArchive("emitters: a name is not UTF-8")
            material, flags = struct.unpack_from("<II", rec, 64)
            radiance = list(struct.unpack_from("<3f", rec, 72))
            reserved = struct.unpack_from("<I", rec, 84)[0]
            if flags & ~1 or (self.strict and reserved):
                raise InvalidArchive("emitters: unknown group flags or a non-zero reserved field")
            irr = [list(struct.unpack_from("<3f", raw, at + 12 * i)) for i in range(n_entries)]
            at += 12 * n_entries
            direct = [decode_rgb9e5(struct.unpack_from("<I", raw, at + 4 * i)[0]) for i in range(texels)]
            at += 4 * texels
            indirect = None
            if flags & 1:
                indirect = [decode_rgb9e5(struct.unpack_from("<I", raw, at + 4 * i)[0]) for i in range(texels)]
            at += 4 * texels
            if any(v != v or v < 0 or v == float("inf") for r in [radiance] + irr for v in r):
                raise InvalidArchive("emitters: values must be finite and non-negative")
            out.append(dict(name=name, material=material, radiance=radiance,
                            entry_irradiance=irr, direct=direct, indirect=indirect))
        self.emitters = out

    def load(self, s, max_raw):
        if s["raw_size"] > max_raw:
            raise InvalidArchive(f"{s['name']} raw size over the limit")
        stored = self.d[s["offset"]:s["offset"] + s["stored_size"]]
        self.check(stored, s["_sum"], s["name"])
        if s["compression"] == 0:
            if s["raw_size"] != s["stored_size"]:
                raise InvalidArchive(f"{s['name']}: raw size differs from stored size")
            return stored
        if s["compression"] == 1:
            return zstd_decompress(stored, s["raw_size"], s["name"])
        raise InvalidArchive(f"{s['name']}: unknown compression {s['compression']}")

    def parse_atlas(self, raw):
        if len(raw) < 16:
            raise InvalidArchive("atlas too short")
        res, tile, ntri, reserved = struct.unpack_from("<IIII", raw, 0)
        if self.strict and reserved:
            raise InvalidArchive("atlas reserved field not zero")
        if not (1 <= res <= MAX_RESOLUTION and 1 <= tile <= min(res, MAX_TILE_SIZE) and res % tile == 0):
            raise InvalidArchive("bad atlas resolution or tile size")
        mask_len = (res * res + 7) // 8
        if ntri > MAX_TRIANGLES or len(raw) != 16 + 24 * ntri + mask_len:
            raise InvalidArchive("atlas size does not match its header")
        uvs = struct.unpack_from(f"<{6 * ntri}f", raw, 16)
        if any(not (0.0 <= v <= 1.0) for v in uvs):
            raise InvalidArchive("atlas UV outside [0, 1]")
        mask = raw[16 + 24 * ntri:]
        used = (res * res) % 8
        if used and mask[-1] >> used:
            raise InvalidArchive("coverage padding bits not zero")
        self.resolution, self.tile_size, self.triangles = res, tile, ntri
        self.covered = sum(bin(b).count("1") for b in mask)

    def parse_entries_clusters(self, er, cr):
        if len(er) % 28 or len(cr) % 56:
            raise InvalidArchive("entries/clusters size not a multiple of the record size")
        entries = []
        for i in range(len(er) // 28):
            px, py, pz, nx, ny, nz, c = struct.unpack_from("<6fI", er, 28 * i)
            vals = (px, py, pz, nx, ny, nz)
            if any(v != v or v in (float("inf"), float("-inf")) for v in vals):
                raise InvalidArchive(f"entry {i} not finite")
            entries.append(dict(position=[px, py, pz], normal=[nx, ny, nz], cluster=c))
        clusters = []
        nxt = 0
        for i in range(len(cr) // 56):
            first, count, *f = struct.unpack_from("<II12f", cr, 56 * i)
            if first != nxt or first + count > len(entries):
                raise InvalidArchive(f"cluster {i} range does not tile the entries")
            if any(e["cluster"] != i for e in entries[first:first + count]):
                raise InvalidArchive(f"entry in cluster {i}'s range names another cluster")
            if any(v != v or abs(v) == float("inf") for v in f) or any(v < 0 for v in f[6:]):
                raise InvalidArchive(f"cluster {i} has invalid floats")
            nxt = first + count
            clusters.append(dict(first=first, count=count, centroid=f[0:3], mean_normal=f[3:6],
                                 energy=f[6:9], peak=f[9:12]))
        if nxt != len(entries):
            raise InvalidArchive("clusters do not cover all entries")
        self.entries, self.clusters = entries, clusters

    def parse_panes(self, s):
        # Section 7: 16-byte header (pane count P, tiles per side S, largest rank, reserved), S^2
        # ranks r_t (u32), P*S^2 f32 scales (tile by tile, pane by pane), then every tile's
        # 3P*r_t f16 coefficients (index (3c + ch)*r_t + k, each times its pane's scale), then
        # every tile's T^2*r_t f16 basis values column by column (index k*T^2 + texel); both f16
        # arrays in 2 byte planes.
        p_count, t = len(self.clusters), self.tile_size
        tps = self.resolution // t
        tiles = tps * tps
        bound = min(t * t, 3 * p_count)
        per_rank = 6 * p_count + 2 * t * t
        fixed = 16 + 4 * tiles + 4 * p_count * tiles
        raw = self.load(s, fixed + tiles * bound * per_rank)
        if len(raw) < 16 + 4 * tiles:
            raise InvalidArchive("panes: shorter than its header and ranks")
        count, stps, max_rank, reserved = struct.unpack_from("<4I", raw, 0)
        if count != p_count or stps != tps:
            raise InvalidArchive("panes header disagrees with atlas/clusters")
        if self.strict and reserved:
            raise InvalidArchive("panes reserved field not zero")
        ranks = list(struct.unpack_from(f"<{tiles}I", raw, 16))
        if any(r > bound for r in ranks) or max(ranks, default=0) != max_rank:
            raise InvalidArchive("panes: a rank over min(T^2, 3P), or the largest rank differs from the header's")
        if len(raw) != fixed + sum(ranks) * per_rank:
            raise InvalidArchive("panes: raw size differs from what the ranks give")
        at = 16 + 4 * tiles
        scales = struct.unpack_from(f"<{p_count * tiles}f", raw, at)
        if any(not 0 <= v < float("inf") for v in scales):
            raise InvalidArchive("panes: scales must be finite and at least 0")
        at += 4 * p_count * tiles
        n = 3 * p_count * sum(ranks)
        halves = struct.unpack(f"<{n}e", bytes(unplane(raw[at:at + 2 * n], 2, raw=True)))
        at += 2 * n
        m = t * t * sum(ranks)
        columns = struct.unpack(f"<{m}e", bytes(unplane(raw[at:at + 2 * m], 2, raw=True)))
        coefficients, bases, k, j = [], [], 0, 0
        for tile, r in enumerate(ranks):
            c = []
            for p in range(p_count):
                scale = scales[tile * p_count + p]
                c.extend(to_f32(v * scale) for v in halves[k:k + 3 * r])
                k += 3 * r
            coefficients.append(c)
            cols = columns[j:j + t * t * r]
            j += t * t * r
            bases.append([cols[kk * t * t + i] for i in range(t * t) for kk in range(r)])
        if any(v != v or abs(v) == float("inf") for part in coefficients + bases for v in part):
            raise InvalidArchive("panes: coefficients and basis values must be finite")
        self.ranks, self.coefficients, self.bases = ranks, coefficients, bases
        self.tps = tps

    def read_pane(self, p):
        """Decoded pane as a row-major list of [r, g, b], plus energy and peak (section 6: binary64
        sums over the tiles in tile order, texels row-major within a tile)."""
        res, t, tps = self.resolution, self.tile_size, self.tps
        texels = [[0.0, 0.0, 0.0] for _ in range(res * res)]
        energy = [0.0, 0.0, 0.0]
        peak = [0.0, 0.0, 0.0]
        for tile, r in enumerate(self.ranks):
            if r == 0:
                continue
            tx, ty = tile % tps, tile // tps
            c, u = self.coefficients[tile], self.bases[tile]
            rows = [c[(3 * p + ch) * r:(3 * p + ch + 1) * r] for ch in range(3)]
            for i in range(t * t):
                ui = u[i * r:(i + 1) * r]
                v = [decode_value(ui, rows[ch]) for ch in range(3)]
                texels[(ty * t + i // t) * res + tx * t + i % t] = v
                for ch in range(3):
                    energy[ch] += v[ch]
                    peak[ch] = max(peak[ch], v[ch])
        return texels, [to_f32(e) for e in energy], peak

    @staticmethod
    def parse_accuracy(a):
        # The bake's own accuracy estimate, optional (formats/prm.md section 3).
        if a is None:
            return None
        def number(v, what):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v or v in (float("inf"), float("-inf")):
                raise InvalidArchive(f"metadata: accuracy {what} is not a finite number")
            return float(v)
        if not isinstance(a, dict) or not isinstance(a.get("lights"), list):
            raise InvalidArchive("metadata: accuracy must be an object with a lights array")
        for k in ("exit_points", "paths", "top_k", "residual_groups"):
            if isinstance(a.get(k), bool) or not isinstance(a.get(k), int) or not 0 <= a[k] < 2**32:
                raise InvalidArchive(f"metadata: accuracy {k} must be an integer in 0 .. 2^32-1")
        lights = []
        for i, l in enumerate(a["lights"]):
            if not isinstance(l, dict) or not isinstance(l.get("position"), list) or len(l["position"]) != 3:
                raise InvalidArchive(f"metadata: accuracy light {i} needs a position of 3 numbers")
            rec = {"position": [number(p, f"light {i} position") for p in l["position"]]}
            for k in ("error", "measured", "reference_noise", "energy", "error_all_clusters", "standard_error"):
                rec[k] = number(l.get(k), f"light {i} {k}")
                if rec[k] < 0:
                    raise InvalidArchive(f"metadata: accuracy light {i} {k} is negative")
            lights.append(rec)
        n = len(lights)
        mean = lambda k: sum(l[k] for l in lights) / n if n else 0.0
        se = (sum(l["standard_error"] ** 2 for l in lights) ** 0.5) / n if n else 0.0
        return dict(exit_points=a["exit_points"], paths=a["paths"], top_k=a["top_k"],
                    residual_groups=a["residual_groups"], lights=lights,
                    mean_error=mean("error"), mean_error_all_clusters=mean("error_all_clusters"),
                    mean_energy=mean("energy"), mean_standard_error=se)

    def summary(self, pane=None):
        out = dict(
            version=self.version,
            file_length=self.file_length,
            checksums_verified=self.checksums_verified,
            sections=[{k: v for k, v in s.items() if not k.startswith("_")} for s in self.sections],
            metadata=self.metadata,
            resolution=self.resolution,
            tile_size=self.tile_size,
            triangles=self.triangles,
            covered_texels=self.covered,
            entries=self.entries,
            entry_energy=self.entry_energy,
            emitters=self.emitters,
            sky=self.sky,
            probes=self.probes,
            probe_rays=self.probe_rays,
            near_field=self.near_field,
            entry_cells=self.entry_cells,
            accuracy=self.accuracy,
            clusters=self.clusters,
            panes=dict(tiles=self.tps * self.tps, ranks=self.ranks, max_rank=max(self.ranks, default=0),
                       basis_bytes=2 * self.tile_size ** 2 * sum(self.ranks),
                       coefficient_bytes=6 * len(self.clusters) * sum(self.ranks) + 4 * len(self.clusters) * len(self.ranks)),
        )
        if pane is not None:
            if not 0 <= pane < len(self.clusters):
                raise InvalidArchive(f"pane {pane} out of range")
            texels, energy, peak = self.read_pane(pane)
            out["pane"] = dict(index=pane, texels=texels, energy=energy, peak=peak)
        return out


def main(argv):
    pane = None
    verify = True
    path = None
    args = list(argv)
    while args:
        a = args.pop(0)
        if a == "--pane" and args:
            try:
                pane = int(args.pop(0))
            except ValueError:
                print("--pane needs an integer", file=sys.stderr)
                return 2
        elif a == "--no-verify":
            verify = False
        elif a in ("-h", "--help"):
            print(__doc__)
            return 0
        elif path is None and not a.startswith("--"):
            path = a
        else:
            print(f"unexpected argument {a!r}\n{__doc__}", file=sys.stderr)
            return 2
    if path is None:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        with open(path, "rb") as f:
            data = f.read()
        r = Reader(data, verify=verify)
        r.parse()
        print(json.dumps(r.summary(pane)))
        return 0
    except NoZstd as e:
        print(str(e), file=sys.stderr)
        return 3
    except (InvalidArchive, struct.error) as e:
        print(f"invalid archive: {e}", file=sys.stderr)
        return 1
    except OSError as e:
        print(f"cannot read {path}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
