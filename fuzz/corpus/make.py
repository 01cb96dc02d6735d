#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets from the repository's fixtures.

Run from anywhere: `python3 fuzz/corpus/make.py`. Standard library only. Seeds are small on
purpose (a fuzzer mutates a 2 KB file many times faster than a 100 KB one) but keep the shape of
the real files: the same headers, fields and encodings, cut down to a few lines, entries,
pixels or faces.
"""

import io
import json
import struct
import urllib.parse
import zipfile
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "tests" / "fixtures"
REFERENCE = FIXTURES / "reference"
DATASET = REFERENCE / "dataset"
OUT = Path(__file__).resolve().parent


def write(target, name, data):
    folder = OUT / target
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(data)


def head_lines(path, n):
    with open(path, "rb") as f:
        return b"".join(f.readline() for _ in range(n))


def bop_csv():
    results = REFERENCE / "results"
    for name in ["noisesmall_synthA-test.csv", "multi_synthA-test.csv", "missing_synthA-test.csv"]:
        write("bop_csv", name, head_lines(results / name, 5))
    for path in sorted((results / "malformed").glob("*.csv")):
        write("bop_csv", "malformed-" + path.name, path.read_bytes())


def bop22_json():
    for path in sorted((FIXTURES / "coco" / "results").glob("*.json")):
        entries = json.loads(path.read_text())[:3]
        write("bop22_json", path.name, json.dumps(entries).encode())


def read_ply(path):
    """(header lines, vertex rows as float tuples, faces as index lists) of a binary PLY with
    float vertex properties and a `list uchar int` face property, as the fixtures are."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    n_vertex = n_face = 0
    props = 0
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            n_vertex = int(words[2])
        elif words[:2] == ["element", "face"]:
            n_face = int(words[2])
        elif words[:2] == ["property", "float"]:
            props += 1
    pos = end
    vertices = []
    for _ in range(n_vertex):
        vertices.append(struct.unpack_from("<%df" % props, data, pos))
        pos += 4 * props
    faces = []
    for _ in range(n_face):
        count = data[pos]
        faces.append(list(struct.unpack_from("<%di" % count, data, pos + 1)))
        pos += 1 + 4 * count
    return header, vertices, faces


def small_mesh(path, n_faces):
    """The first `n_faces` faces of a fixture mesh and the vertices they use, renumbered."""
    header, vertices, faces = read_ply(path)
    faces = faces[:n_faces]
    used = sorted({i for f in faces for i in f})
    index = {old: new for new, old in enumerate(used)}
    vertex_props = [l for l in header if l.startswith("property float")]
    return [vertices[i] for i in used], [[index[i] for i in f] for f in faces], vertex_props


def ply():
    for obj in [1, 3]:
        vertices, faces, props = small_mesh(DATASET / "models" / ("obj_%06d.ply" % obj), 6)
        head = (
            ["ply", "format binary_little_endian 1.0", "element vertex %d" % len(vertices)]
            + props
            + ["element face %d" % len(faces), "property list uchar int vertex_indices", "end_header"]
        )
        body = b"".join(struct.pack("<%df" % len(v), *v) for v in vertices)
        body += b"".join(struct.pack("<B%di" % len(f), len(f), *f) for f in faces)
        write("ply", "obj_%06d-binary.ply" % obj, ("\n".join(head) + "\n").encode() + body)
        ascii_head = [l if not l.startswith("format") else "format ascii 1.0" for l in head]
        lines = [" ".join("%g" % x for x in v) for v in vertices]
        lines += [" ".join(str(x) for x in [len(f)] + f) for f in faces]
        write("ply", "obj_%06d-ascii.ply" % obj, ("\n".join(ascii_head + lines) + "\n").encode())


def png_chunks(data):
    pos = 8
    while pos < len(data):
        (length,) = struct.unpack_from(">I", data, pos)
        kind = data[pos + 4 : pos + 8]
        yield kind, data[pos + 8 : pos + 8 + length]
        pos += 12 + length


def paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def read_depth_png(path):
    """(width, height, rows of big-endian 16-bit samples) of a 16-bit grayscale PNG."""
    data = path.read_bytes()
    idat = b""
    for kind, body in png_chunks(data):
        if kind == b"IHDR":
            width, height, bits, color = struct.unpack_from(">IIBB", body)
            assert (bits, color) == (16, 0), path
        elif kind == b"IDAT":
            idat += body
    raw = zlib.decompress(idat)
    stride, bpp = width * 2, 2
    rows, prev = [], bytearray(stride)
    for y in range(height):
        start = y * (stride + 1)
        kind, row = raw[start], bytearray(raw[start + 1 : start + 1 + stride])
        for x in range(stride):
            a = row[x - bpp] if x >= bpp else 0
            b, c = prev[x], prev[x - bpp] if x >= bpp else 0
            row[x] = (row[x] + [0, a, b, (a + b) // 2, paeth(a, b, c)][kind]) & 0xFF
        rows.append(bytes(row))
        prev = row
    return width, height, rows


def crop(rows, x0, y0, w, h):
    return [row[2 * x0 : 2 * (x0 + w)] for row in rows[y0 : y0 + h]]


def png_file(w, h, rows, filter_type):
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    raw = b""
    prev = bytes(2 * w)
    for row in rows:
        if filter_type == 1:  # Sub
            out = bytes((row[i] - (row[i - 2] if i >= 2 else 0)) & 0xFF for i in range(len(row)))
        elif filter_type == 2:  # Up
            out = bytes((row[i] - prev[i]) & 0xFF for i in range(len(row)))
        else:
            out = row
        raw += bytes([filter_type]) + out
        prev = row
    ihdr = struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


def tiff_file(w, h, rows):
    """A baseline little-endian TIFF, 16-bit grayscale, uncompressed, one strip (as ITODD's
    depth images are, but small)."""
    pixels = b"".join(
        struct.pack("<%dH" % w, *struct.unpack(">%dH" % w, row)) for row in rows
    )
    entries = [
        (256, 3, 1, w),  # ImageWidth
        (257, 3, 1, h),  # ImageLength
        (258, 3, 1, 16),  # BitsPerSample
        (259, 3, 1, 1),  # Compression: none
        (262, 3, 1, 1),  # Photometric: black is zero
        (273, 4, 1, 8),  # StripOffsets: right after the header
        (277, 3, 1, 1),  # SamplesPerPixel
        (278, 3, 1, h),  # RowsPerStrip
        (279, 4, 1, len(pixels)),  # StripByteCounts
    ]
    ifd_at = 8 + len(pixels)
    out = b"II*\x00" + struct.pack("<I", ifd_at) + pixels
    out += struct.pack("<H", len(entries))
    for tag, kind, count, value in entries:
        value_bytes = struct.pack("<H", value) + b"\x00\x00" if kind == 3 else struct.pack("<I", value)
        out += struct.pack("<HHI", tag, kind, count) + value_bytes
    return out + struct.pack("<I", 0)


def depth():
    for scene, image in [(1, 0), (2, 3)]:
        path = DATASET / "test" / ("%06d" % scene) / "depth" / ("%06d.png" % image)
        width, height, rows = read_depth_png(path)
        # A window around the image centre, where the objects are.
        w, h = 16, 12
        part = crop(rows, width // 2 - w // 2, height // 2 - h // 2, w, h)
        for filter_type in [0, 1, 2]:
            write("depth_png", "%06d_%06d-filter%d.png" % (scene, image, filter_type), png_file(w, h, part, filter_type))
        write("depth_tiff", "%06d_%06d.tif" % (scene, image), tiff_file(w, h, part))


def zip_bytes(entries, method=zipfile.ZIP_DEFLATED):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", method) as z:
        for name, data in entries:
            # A fixed date, so that the seeds are the same bytes at every run.
            info = zipfile.ZipInfo(name, date_time=(2024, 6, 1, 12, 0, 0))
            info.compress_type = method
            z.writestr(info, data)
    return buf.getvalue()


def result_lines(name, n):
    return head_lines(REFERENCE / "results" / name, n)


def archive():
    """Zip uploads as archivers write them: a top folder, macOS's resource forks, Stored and
    Deflate entries, and the entries the service refuses (other files, paths leaving it)."""
    noisy, multi = result_lines("noisesmall_synthA-test.csv", 5), result_lines("multi_synthA-test.csv", 5)
    write("archive", "folder-deflate.zip", zip_bytes([
        ("results/", b""),
        ("results/noisy_synthA-test.csv", noisy),
        ("results/multi_synthB-test.csv", multi),
        ("__MACOSX/results/._noisy_synthA-test.csv", b"\x00\x05\x16\x07" + bytes(12)),
    ]))
    write("archive", "stored.zip", zip_bytes([("noisy_synthA-test.csv", noisy)], zipfile.ZIP_STORED))
    write("archive", "refused.zip", zip_bytes([
        ("noisy_synthA-test.csv", noisy),
        ("readme.txt", b"hello"),
        ("../multi_synthA-test.csv", multi),
    ]))


BOUNDARY = b"------------------------8c3c1e2a0f4b7d95"


def multipart_body(fields, files):
    """A multipart/form-data body as browsers and curl write it, behind the line naming its
    boundary (the target's input: first line the boundary, the rest the body)."""
    out = b""
    for name, value in fields:
        out += b"--" + BOUNDARY + b'\r\nContent-Disposition: form-data; name="' + name + b'"\r\n\r\n' + value + b"\r\n"
    for filename, kind, data in files:
        out += (b"--" + BOUNDARY + b'\r\nContent-Disposition: form-data; name="file"; filename="' + filename
                + b'"\r\nContent-Type: ' + kind + b"\r\n\r\n" + data + b"\r\n")
    return BOUNDARY + b"\n" + out + b"--" + BOUNDARY + b"--\r\n"


def multipart():
    noisy = result_lines("noisesmall_synthA-test.csv", 5)
    write("multipart", "api-upload", multipart_body(
        [(b"method", b"CosyPose"), (b"visibility", b"public"), (b"protocol", b"bop19,eccv18")],
        [(b"noisy_synthA-test.csv", b"text/csv", noisy)]))
    write("multipart", "browser-form", multipart_body(
        [(b"csrf", b"3f9a0c"), (b"method", b"Caf\xc3\xa9 Pose"), (b"team", b"vision-lab"),
         (b"dataset", b"synthA"), (b"protocol", b"bop24"), (b"description", b"Two stages:\r\ndetect, refine."),
         (b"paper_url", b"https://arxiv.org/abs/2010.00000"), (b"code_url", b""), (b"training_data", b"synthetic"),
         (b"modality", b"rgb-d"), (b"onboarding", b"model-based"), (b"objects", b"seen"),
         (b"hardware", b"1x RTX 3090"), (b"anonymous", b"true"), (b"publish", b"on")],
        [(b"C:\\results\\noisy_synthA-test.csv", b"text/csv", noisy), (b"", b"application/octet-stream", b"")]))
    write("multipart", "zip-upload", multipart_body(
        [(b"method", b"zipped")],
        [(b"all.zip", b"application/zip", zip_bytes([("noisy_synthA-test.csv", noisy)]))]))


def forms():
    """The first byte chooses (see fuzz_targets/forms.rs): even, the method edit form; odd, a
    query string."""
    write("forms", "method-edit", b"\x00" + b"csrf=3f9a0c&description=Two+stages%3A+detect%2C+refine.&authors=A.+B%C3%A9&year=2024"
          b"&paper_url=https%3A%2F%2Farxiv.org%2Fabs%2F2010.00000&code_url=&training_data=synthetic"
          b"&detection_modality=rgb&modality=rgb-d&refinement=ICP&detections=default&model_scope=per-object"
          b"&hardware=1x+RTX+3090&onboarding=model-based&objects=seen&anonymous=true")
    write("forms", "board-query", b"\x01" + b"dataset=synthA&sort=bop19&training=real&modality=rgb-d&objects=unseen"
          b"&onboarding=model-free&group=core&curves=3,7&page=2&protocol=bop19")
    write("forms", "page-query", b"\x01" + b"page=12&visibility=public&protocol=bop22-seg&next=%2Faccount")


# The dataset target's first byte chooses the file its other bytes replace (see
# fuzz_targets/dataset_json.rs): the seeds are the fixture's own files behind their selector.
DATASET_FILES = [
    "test/000001/scene_gt.json",
    "test/000001/scene_camera.json",
    "test/000001/scene_gt_info.json",
    "models/models_info.json",
    "test_targets_bop19.json",
    "camera.json",
]


def dataset_json():
    for selector, name in enumerate(DATASET_FILES):
        data = (DATASET / name).read_bytes()
        write("dataset_json", "%d-%s" % (selector, name.replace("/", "_")), bytes([selector]) + data)


# The largest input a run tries (libFuzzer's -max_len; see fuzz/bounds.sh).
MAX_LEN = 65536


def largest():
    """One valid input per target, as large as a run's inputs may be (at most MAX_LEN bytes),
    written to fuzz/largest/<target>: the time and memory it takes set the bounds of
    fuzz/bounds.sh. Not seeds: a fuzzer mutates small inputs faster."""
    out = OUT.parent / "largest"
    out.mkdir(exist_ok=True)

    def fill(make, n_max):
        """make(n) for the largest n whose output fits MAX_LEN."""
        best, lo, hi = make(1), 1, n_max
        while lo <= hi:
            mid = (lo + hi) // 2
            data = make(mid)
            if len(data) <= MAX_LEN:
                best, lo = data, mid + 1
            else:
                hi = mid - 1
        return best

    results = REFERENCE / "results"
    header, *rows = (results / "multi_synthA-test.csv").read_bytes().splitlines(keepends=True)
    for other in ["noiselarge_synthA-test.csv", "noisemedium_synthA-test.csv", "extra_synthA-test.csv"]:
        rows += (results / other).read_bytes().splitlines(keepends=True)[1:]
    csv = fill(lambda n: header + b"".join(rows[:n]), len(rows))
    (out / "bop_csv").write_bytes(csv)

    entries = json.loads((FIXTURES / "coco" / "results" / "many_tudl-test.json").read_text())
    (out / "bop22_json").write_bytes(fill(lambda n: json.dumps(entries[:n]).encode(), len(entries)))

    def mesh(n):
        vertices, faces, props = small_mesh(DATASET / "models" / "obj_000001.ply", n)
        head = (["ply", "format binary_little_endian 1.0", "element vertex %d" % len(vertices)] + props
                + ["element face %d" % len(faces), "property list uchar int vertex_indices", "end_header"])
        body = b"".join(struct.pack("<%df" % len(v), *v) for v in vertices)
        body += b"".join(struct.pack("<B%di" % len(f), len(f), *f) for f in faces)
        return ("\n".join(head) + "\n").encode() + body
    (out / "ply").write_bytes(fill(mesh, 100000))

    width, height, rows16 = read_depth_png(DATASET / "test" / "000001" / "depth" / "000000.png")
    def png(n):
        w, h = min(width, 4 * n), min(height, 3 * n)
        return png_file(w, h, crop(rows16, (width - w) // 2, (height - h) // 2, w, h), 2)
    (out / "depth_png").write_bytes(fill(png, min(width // 4, height // 3)))
    def tif(n):
        w, h = min(width, 4 * n), min(height, 3 * n)
        return tiff_file(w, h, crop(rows16, (width - w) // 2, (height - h) // 2, w, h))
    (out / "depth_tiff").write_bytes(fill(tif, min(width // 4, height // 3)))

    # models_info.json of many objects: the one file of a dataset that stands alone.
    info = json.loads((DATASET / "models" / "models_info.json").read_text())
    first = next(iter(info.values()))
    def models(n):
        return bytes([3]) + json.dumps({str(i + 1): first for i in range(n)}, indent=1).encode()
    (out / "dataset_json").write_bytes(fill(models, 100000))

    def zipped(n):
        return zip_bytes([("results/r%d_synthA-test.csv" % i, csv[: 4096 * (1 + i % 4)]) for i in range(n)])
    (out / "archive").write_bytes(fill(zipped, 20))

    (out / "multipart").write_bytes(fill(lambda n: multipart_body(
        [(b"method", b"CosyPose"), (b"visibility", b"public")],
        [(b"multi_synthA-test.csv", b"text/csv", csv[: n * 1024])]), 64))

    # The longest form the fields allow (a description is at most 10,000 characters).
    description = ("Two stages: detect, then refine with ICP. " * 240)[:10000]
    (out / "forms").write_bytes(b"\x00" + urllib.parse.urlencode({
        "csrf": "3f9a0c", "description": description, "authors": "A. B\u00e9, C. D", "year": "2024",
        "paper_url": "https://arxiv.org/abs/2010.00000", "training_data": "synthetic", "modality": "rgb-d",
        "refinement": "ICP " * 100, "detections": "default", "model_scope": "per-object",
        "hardware": "1x RTX 3090", "onboarding": "model-based", "objects": "seen", "anonymous": "true",
    }).encode())


if __name__ == "__main__":
    bop_csv()
    bop22_json()
    ply()
    depth()
    dataset_json()
    archive()
    multipart()
    forms()
    largest()
