#!/usr/bin/env python3
"""Writes the fuzz seed corpora under fuzz/seeds/<target>/ from the real files
in ../shared/data and scenes/*.toml. Every seed is small: real headers with
their sizes cut down to a few voxels and a payload of real samples (a slab
from the middle of the volume), plus a few type/endian/encoding variants and
the untouched header with a tiny payload (the truncation path). The image
targets get hand-written EXRs and PNGs, scenes/photo.jpg whole and cut short,
and snell's own 8x8 renders (PNG, colour and hit EXRs, whole and as a
region) when target/release/snell is built.

Run from the repository root: python3 fuzz/make-seeds.py
"""
import gzip
import os
import re
import struct
import sys
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "..", "shared", "data")
OUT = os.path.join(ROOT, "fuzz", "seeds")
TYPE_SIZE = {"uint8": 1, "int8": 1, "uint16": 2, "int16": 2, "int32": 4,
             "uint32": 4, "float": 4, "double": 8}


def write(target, name, data):
    d = os.path.join(OUT, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def split_nrrd(path):
    raw = open(path, "rb").read()
    end = raw.index(b"\n\n")
    return raw[:end].decode(), raw[end + 2:]


def middle_slab(header, payload, nbytes):
    """nbytes of decoded samples from the middle of the volume."""
    if "encoding: gzip" in header:
        d = zlib.decompressobj(16 + zlib.MAX_WBITS)
        out = b""
        chunk = 1 << 16
        pos = 0
        while pos < len(payload) and len(out) < 8 << 20:
            out += d.decompress(payload[pos:pos + chunk])
            pos += chunk
        payload = out
    mid = len(payload) // 2
    return payload[mid:mid + nbytes]


SEED_DIMS = (4, 3, 2)


def scans():
    """Each real NRRD scan: its stem, header, payload, type and SEED_DIMS'
    worth of its samples from the middle of the volume."""
    for name in sorted(os.listdir(DATA)):
        if not name.endswith(".nrrd"):
            continue
        header, payload = split_nrrd(os.path.join(DATA, name))
        ty = re.search(r"type: (\w+)", header).group(1)
        n = SEED_DIMS[0] * SEED_DIMS[1] * SEED_DIMS[2]
        yield name[:-5], header, payload, ty, middle_slab(header, payload, n * TYPE_SIZE[ty])


def nrrd_seeds():
    for stem, header, payload, ty, samples in scans():
        dims = SEED_DIMS
        small = re.sub(r"sizes: .*", "sizes: %d %d %d" % dims, header)
        # Attached: gzip as in the real file, and raw.
        write("nrrd", stem + "-gzip.nrrd", (small + "\n\n").encode() + gzip.compress(samples, mtime=0))
        write("nrrd", stem + "-raw.nrrd",
              (small.replace("encoding: gzip", "encoding: raw") + "\n\n").encode() + samples)
        # The real header untouched, with a tiny payload: the truncation path.
        write("nrrd", stem + "-truncated.nrrd", (header + "\n\n").encode() + payload[:64])
        # Detached: [u16 header length][header][data file].
        for enc, data_name, body in [("raw", "in.raw", samples),
                                      ("gzip", "in.raw.gz", gzip.compress(samples, mtime=0))]:
            h = re.sub(r"encoding: \w+", "encoding: " + enc, small)
            h += "\ndata file: %s\n" % data_name
            hb = h.encode()
            write("nhdr", "%s-%s.nhdr" % (stem, enc), struct.pack("<H", len(hb)) + hb + body)
    # Types, endians and spacing forms the real files do not use.
    base = "NRRD0004\ntype: %s\ndimension: 3\nsizes: 3 2 2\n%s\nencoding: raw\n%s\n"
    for ty, fmt in [("float", "f"), ("double", "d"), ("int16", "h"), ("uint32", "I"),
                    ("int8", "b"), ("int32", "i")]:
        for endian, ch in [("little", "<"), ("big", ">")]:
            vals = [i * 3 - 5 if fmt.islower() else i * 3 for i in range(12)]
            body = struct.pack(ch + fmt * 12, *vals)
            spacing = "spacings: 0.5 1 2" if ty in ("float", "int8") else \
                "space directions: (0.5,0,0) (0,1,0) (0,0,2)"
            hdr = base % (ty, "endian: " + endian, spacing)
            write("nrrd", "%s-%s.nrrd" % (ty, endian), hdr.encode() + b"\n" + body)
            hb = (hdr + "data file: in.raw\nbyte skip: 0\nline skip: 0\n").encode()
            write("nhdr", "%s-%s.nhdr" % (ty, endian), struct.pack("<H", len(hb)) + hb + body)
    # Ascii data, attached and detached; data split over two files (the
    # harness writes one data file, so the list names it twice).
    text = b"1 2, 3\n4 5 6\n7 8 9 10 11 12 13\n"
    hdr = "NRRD0005\ntype: short\ndimension: 3\nsizes: 3 2 2\nencoding: ascii\n"
    write("nrrd", "ascii.nrrd", (hdr + "\n").encode() + text)
    hb = (hdr + "data file: in.raw\n").encode()
    write("nhdr", "ascii.nhdr", struct.pack("<H", len(hb)) + hb + text)
    hb = b"NRRD0005\ntype: uchar\ndimension: 3\nsizes: 3 2 2\nencoding: raw\ndata file: LIST\nin.raw\nin.raw\n"
    write("nhdr", "list.nhdr", struct.pack("<H", len(hb)) + hb + bytes(range(6)))
    hb = b"NRRD0005\ntype: uchar\ndimension: 3\nsizes: 3 2 2\nencoding: gzip\nbyte skip: -1\ndata file: LIST 2\nin.raw.gz\nin.raw.gz\n"
    write("nhdr", "list-gzip.nhdr", struct.pack("<H", len(hb)) + hb + gzip.compress(bytes(range(9)), mtime=0))


def nifti_seeds():
    src = os.path.join(DATA, "mni152-2009a-t1.nii.gz")
    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
    head = d.decompress(open(src, "rb").read()[:1 << 20])
    hdr = bytearray(head[:348])
    endian = "<" if struct.unpack("<i", hdr[:4])[0] == 348 else ">"
    datatype, bitpix = struct.unpack(endian + "hh", hdr[70:74])
    vox = int(struct.unpack(endian + "f", hdr[108:112])[0])
    size = bitpix // 8
    dims = (4, 3, 2)
    struct.pack_into(endian + "8h", hdr, 40, 3, *dims, 1, 1, 1, 1)
    struct.pack_into(endian + "f", hdr, 108, 352.0)
    data = head[vox:]
    mid = len(data) // 2
    body = bytes(hdr) + b"\0\0\0\0" + data[mid:mid + dims[0] * dims[1] * dims[2] * size]
    # Mode byte: 1 = compress the rest, 0 = as is.
    write("nifti", "mni152-small-gz", b"\x01" + body)
    write("nifti", "mni152-small", b"\x00" + body)
    # The real header untouched with a tiny payload.
    write("nifti", "mni152-truncated", b"\x00" + bytes(head[:352]) + data[:64])
    # Scaled float variant, big endian.
    fl = bytearray(348)
    struct.pack_into(">i", fl, 0, 348)
    struct.pack_into(">8h", fl, 40, 3, 3, 2, 2, 1, 1, 1, 1)
    struct.pack_into(">hh", fl, 70, 16, 32)
    struct.pack_into(">8f", fl, 76, 1.0, 0.5, 1.0, 2.0, 1, 1, 1, 1)
    struct.pack_into(">f", fl, 108, 352.0)
    struct.pack_into(">ff", fl, 112, 2.0, -1.0)
    fl[344:348] = b"n+1\0"
    vals = struct.pack(">12f", *[i * 0.25 for i in range(12)])
    write("nifti", "float-big-scaled", b"\x00" + bytes(fl) + b"\0\0\0\0" + vals)


def raw_seeds():
    src = os.path.join(DATA, "headsq-quarter-ct_64x64x93_u16le.raw")
    data = open(src, "rb").read()
    mid = len(data) // 2
    for dims, ty, endian, offset in [((8, 8, 2), 2, 0, 0), ((4, 4, 4), 2, 1, 6),
                                      ((2, 3, 4), 0, 0, 0), ((3, 3, 3), 7, 0, 0)]:
        n = dims[0] * dims[1] * dims[2]
        size = [1, 1, 2, 2, 4, 4, 4, 8][ty]
        head = struct.pack("<3HBBH3fB", *dims, ty, endian, offset, 1.0, 1.0, 2.5, 0)
        body = data[mid - offset:mid + n * size]
        write("raw", "%dx%dx%d-t%d-e%d-o%d" % (dims + (ty, endian, offset)), head + body)


def metaimage_seeds():
    """[len: u16 LE][header][payload]: real samples from the middle of each
    scan behind MetaImage headers as ITK writes them, attached and detached
    (the detached ones name in.raw, where the harness puts the payload)."""
    types = {"uint8": "MET_UCHAR", "int8": "MET_CHAR", "uint16": "MET_USHORT",
             "int16": "MET_SHORT", "int32": "MET_INT", "uint32": "MET_UINT",
             "float": "MET_FLOAT", "double": "MET_DOUBLE"}

    def seed(name, fields, payload):
        hb = fields.encode()
        write("metaimage", name, struct.pack("<H", len(hb)) + hb + payload)

    for stem, header, _, ty, body in scans():
        msb = "True" if "endian: big" in header else "False"
        head = ("ObjectType = Image\nNDims = 3\nBinaryData = True\n"
                "BinaryDataByteOrderMSB = %s\n%%sTransformMatrix = 1 0 0 0 1 0 0 0 1\n"
                "Offset = 0 0 0\nAnatomicalOrientation = RAI\nElementSpacing = 1 1 1.5\n"
                "DimSize = 4 3 2\nElementType = %s\nElementDataFile = %%s\n" % (msb, types[ty]))
        seed(stem + "-local", head % ("", "LOCAL"), body)
        packed = zlib.compress(body)
        seed(stem + "-zlib", head % ("CompressedData = True\nCompressedDataSize = %d\n"
                                     % len(packed), "LOCAL"), packed)
        seed(stem + "-zlib-nosize", head % ("CompressedData = True\n", "LOCAL"), packed)
        seed(stem + "-detached", head % ("HeaderSize = 3\n", "in.raw"), b"abc" + body)
        seed(stem + "-at-end", head % ("HeaderSize = -1\n", "in.raw"), b"xyz" + body)
        seed(stem + "-truncated", head % ("", "LOCAL"), body[:5])


def scene_seeds():
    scenes = os.path.join(ROOT, "scenes")
    for name in sorted(os.listdir(scenes)):
        if name.endswith(".toml"):
            # As is: the harness resolves paths beside scenes/.
            text = open(os.path.join(scenes, name), "rb").read()
            write("scene", name, text)
            write("scene", name + "-set", text + b"\0surface.filter=linear\nrender.traversal=step\n")


def exr(channels, width, height, origin=(0, 0), full=None):
    """An uncompressed scanline OpenEXR: channels as (name, pixel type (0
    uint, 1 half, 2 float), values row by row), in a display window of
    `full` with the data window at `origin`."""
    full = full or (width, height)
    channels = sorted(channels)

    def attr(name, kind, value):
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", t, 0, 1, 1)
                      for n, t, _ in channels) + b"\0"
    x0, y0 = origin
    header = (b"\x76\x2f\x31\x01" + struct.pack("<i", 2)
              + attr("channels", "chlist", chlist)
              + attr("compression", "compression", b"\0")
              + attr("dataWindow", "box2i", struct.pack("<4i", x0, y0, x0 + width - 1, y0 + height - 1))
              + attr("displayWindow", "box2i", struct.pack("<4i", 0, 0, full[0] - 1, full[1] - 1))
              + attr("lineOrder", "lineOrder", b"\0")
              + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attr("screenWindowCenter", "v2f", struct.pack("<2f", 0, 0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
              + b"\0")
    fmt = {0: "I", 1: "e", 2: "f"}
    lines = []
    for y in range(height):
        row = b"".join(struct.pack("<%d%s" % (width, fmt[t]), *v[y * width:(y + 1) * width])
                       for _, t, v in channels)
        lines.append(struct.pack("<ii", y0 + y, len(row)) + row)
    offset = len(header) + 8 * height
    table = b""
    for line in lines:
        table += struct.pack("<Q", offset)
        offset += len(line)
    return header + table + b"".join(lines)


def exr_seeds():
    """Hit-position, colour and part EXRs as snell writes them (rendered by
    target/release/snell when it is built), and hand-written uncompressed
    ones with other pixel types."""
    w, h = 4, 3
    n = w * h
    u = [0.25 * i for i in range(n)]
    v = [-0.5 * i for i in range(n)]
    events = [float(i % 3) for i in range(n)]
    write("exr", "hits-float.exr", exr([("u", 2, u), ("v", 2, v), ("events", 2, events)], w, h))
    write("exr", "hits-part.exr", exr([("u", 2, u), ("v", 2, v), ("events", 2, events)],
                                      w, h, origin=(2, 5), full=(8, 9)))
    write("exr", "rgb-half.exr", exr([(c, 1, [i / n for i in range(n)]) for c in "RGB"], w, h))
    write("exr", "rgb-uint.exr", exr([(c, 0, list(range(n))) for c in "RGB"], w, h))
    for name, data in snell_outputs().items():
        if name.endswith(".exr"):
            write("exr", name, data)


def snell_outputs():
    """An 8×8 render of the sphere scene, whole and as a region, by
    target/release/snell if it is built: {file name: bytes} of its PNGs,
    colour EXRs and hit EXRs."""
    snell = os.path.join(ROOT, "target", "release", "snell")
    if not os.path.exists(snell):
        print("no target/release/snell: no seeds of snell's own images", file=sys.stderr)
        return {}
    import subprocess
    import tempfile
    scene = os.path.join(ROOT, "scenes", "sphere.toml")
    files = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in [("frame", []), ("region", ["--region", "2,3,6,7"])]:
            out = {"snell-%s%s" % (name, suffix): os.path.join(tmp, name + suffix)
                   for suffix in [".png", ".exr", "-hits.exr"]}
            subprocess.run([snell, "render", scene, "--set", "image.width=8", "--set",
                            "image.height=8", "-q", "-o", out["snell-%s.png" % name],
                            "--exr", out["snell-%s.exr" % name],
                            "--hits", out["snell-%s-hits.exr" % name]] + extra,
                           check=True, capture_output=True)
            files.update((k, open(v, "rb").read()) for k, v in out.items())
    return files


def png(width, height, color_type, depth, rows, palette=None):
    """A PNG of raw rows (each with its filter byte added)."""
    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    body = b"".join(b"\0" + r for r in rows)
    out = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, depth,
                                                              color_type, 0, 0, 0))
    if palette:
        out += chunk(b"PLTE", palette)
    return out + chunk(b"IDAT", zlib.compress(body)) + chunk(b"IEND", b"")


def photo_seeds():
    """Small PNGs of each colour type and depth, and the repository's
    photograph (a JPEG) whole and cut short."""
    w, h = 5, 4
    write("photo", "rgb8.png", png(w, h, 2, 8, [bytes(c for x in range(w) for c in (x * 50, y * 60, 128))
                                               for y in range(h)]))
    write("photo", "gray8.png", png(w, h, 0, 8, [bytes(range(y, y + w)) for y in range(h)]))
    write("photo", "rgba16.png", png(w, h, 6, 16, [struct.pack(">%dH" % (4 * w), *range(4 * w))
                                                   for _ in range(h)]))
    write("photo", "palette.png", png(w, h, 3, 8, [bytes(x % 3 for x in range(w)) for _ in range(h)],
                                      palette=bytes(range(9))))
    jpeg = open(os.path.join(ROOT, "scenes", "photo.jpg"), "rb").read()
    write("photo", "photo.jpg", jpeg)
    write("photo", "photo-truncated.jpg", jpeg[:len(jpeg) // 2])
    for name, data in snell_outputs().items():
        if name.endswith(".png"):
            write("photo", name, data)


if __name__ == "__main__":
    nrrd_seeds()
    nifti_seeds()
    raw_seeds()
    metaimage_seeds()
    scene_seeds()
    exr_seeds()
    photo_seeds()
    for t in sorted(os.listdir(OUT)):
        files = os.listdir(os.path.join(OUT, t))
        total = sum(os.path.getsize(os.path.join(OUT, t, f)) for f in files)
        print("%s: %d seeds, %d bytes" % (t, len(files), total), file=sys.stderr)
