#!/usr/bin/env python3
"""Writes the fuzz seed corpora under fuzz/seeds/<target>/ from the real files
in ../shared/data and scenes/*.toml. Every seed is small: real headers with
their sizes cut down to a few voxels and a payload of real samples (a slab
from the middle of the volume), plus a few type/endian/encoding variants and
the untouched header with a tiny payload (the truncation path).

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


if __name__ == "__main__":
    nrrd_seeds()
    nifti_seeds()
    raw_seeds()
    metaimage_seeds()
    scene_seeds()
    for t in sorted(os.listdir(OUT)):
        files = os.listdir(os.path.join(OUT, t))
        total = sum(os.path.getsize(os.path.join(OUT, t, f)) for f in files)
        print("%s: %d seeds, %d bytes" % (t, len(files), total), file=sys.stderr)
