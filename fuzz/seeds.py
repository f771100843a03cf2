#!/usr/bin/env python3
"""Writes the seed inputs of the fuzz targets into fuzz/corpus/TARGET/seed_*: small valid files
of every kind a user gives femu (decks, Gmsh meshes, measured CSVs, study files, PNG, TIFF,
DICOM, NIfTI), from which libFuzzer mutates. Needs Pillow (PNG, TIFF); DICOM and NIfTI are
written byte by byte. Run from the repository root: python3 fuzz/seeds.py"""

import struct
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "fuzz" / "corpus"

DECK = """*HEADING
two quads
*NODE, NSET=ALL
1, 0.0, 0.0
2, 1.0, 0.0
3, 2.0, 0.0
4, 0.0, 1.0
5, 1.0, 1.0
6, 2.0, 1.0
*ELEMENT, TYPE=CPE4H, ELSET=FAT
1, 1, 2, 5, 4
2, 2, 3, 6, 5
*MATERIAL, NAME=FATMAT
*HYPERELASTIC, NEO HOOKE
0.0008, 30.8
*SOLID SECTION, ELSET=FAT, MATERIAL=FATMAT
*NSET, NSET=LEFT
1, 4
*BOUNDARY
LEFT, 1, 2
*STEP, NLGEOM
*STATIC
0.1, 1.0
*DLOAD
2, P2, 0.0005
*END STEP
"""

TRIANGLES = """*NODE
1, 0, 0
2, 1, 0
3, 0, 1
4, 1, 1
*ELEMENT, TYPE=CPE3, ELSET=E
1, 1, 2, 4
2, 1, 4, 3
*ELSET, ELSET=ALL, GENERATE
1, 2, 1
*MATERIAL, NAME=M
*HYPERELASTIC, MOONEY-RIVLIN
0.001, 0.0005, 10.0
*SOLID SECTION, ELSET=ALL, MATERIAL=M
*NSET, NSET=BOT
1, 2
*BOUNDARY
BOT, 1, 2
3, 1, 1, 0.0
*STEP
*STATIC
1.0, 1.0
*CLOAD
4, 2, -0.001
*END STEP
"""

CSV = """# x,y in mm (model frame), displacements in mm
x,y,ux,uy,sx,sy
-40.0,0.0,0.010,-0.020,0.01,0.01
-36.0,3.0,0.012,-0.018,0.01,0.02
-32.0,6.0,0.011,-0.021,0.02,0.01
"""

CSV_WEIGHTS = "x,y,ux,uy,w\n-40,0,0.01,-0.02,1\n-36,3,0.012,-0.018,0.5\n"

CSV_PLAIN = "x,y,ux,uy\n-40,0,0.01,-0.02\n-36,3,0.012,-0.018\n"

STUDY = """[model]
elements = 700
element = "cpe4h"
[materials.FAT]
c10_kpa = 0.8
d_per_mpa = 30.8
[[test]]
kind = "contention"
pressure_mmhg = 20.0
[[test]]
kind = "compression"
side = "anterior"
force_n_per_mm = 0.1
[grid]
counts = [16, 16]
[noise]
sigma_mm = 0.0176
[measurement]
source = "virtual"
[identification]
test = "compression"
grouped = true
bounds_factor = 4.0
starts = 1
"""

CONVERGENCE = """[convergence]
target_elements = [800, 1600, 3200]
"""


def write(target, name, data):
    d = CORPUS / target
    d.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    (d / f"seed_{name}").write_bytes(data)


def image_bytes(img, fmt):
    import io

    b = io.BytesIO()
    img.save(b, format=fmt)
    return b.getvalue()


def speckle(w, h):
    return Image.frombytes("L", (w, h), bytes((i * 37 + (i // w) * 11) % 251 for i in range(w * h)))


def labels(w, h):
    px = bytearray()
    for j in range(h):
        for i in range(w):
            r = ((i - w / 2) ** 2 + (j - h / 2) ** 2) ** 0.5
            px.append(7 if r < 2 else 2 if r < 5 else 1 if r < 8 else 0)
    return Image.frombytes("L", (w, h), bytes(px))


def element(group, elem, vr, value):
    """One data element in explicit VR little endian."""
    if len(value) % 2:
        value += b"\0" if vr in ("UI", "OB") else b" "
    head = struct.pack("<HH", group, elem) + vr.encode()
    if vr in ("OB", "OW", "UN", "SQ", "UT"):
        return head + b"\0\0" + struct.pack("<I", len(value)) + value
    return head + struct.pack("<H", len(value)) + value


def dicom(w, h, frames):
    """An Ultrasound Multi-frame Image (explicit VR little endian), 8-bit grey."""
    sop = b"1.2.840.10008.5.1.4.1.1.6.1"
    meta = (
        element(2, 0x0001, "OB", b"\0\1")
        + element(2, 0x0002, "UI", sop)
        + element(2, 0x0003, "UI", b"1.2.3.4.5.6")
        + element(2, 0x0010, "UI", b"1.2.840.10008.1.2.1")
    )
    meta = element(2, 0x0000, "UL", struct.pack("<I", len(meta))) + meta
    us = lambda v: struct.pack("<H", v)
    pixels = bytes((k * 37) % 251 for k in range(w * h * frames))
    data = (
        element(0x0008, 0x0016, "UI", sop)
        + element(0x0008, 0x0018, "UI", b"1.2.3.4.5.6")
        + element(0x0028, 0x0002, "US", us(1))
        + element(0x0028, 0x0004, "CS", b"MONOCHROME2")
        + element(0x0028, 0x0008, "IS", str(frames).encode())
        + element(0x0028, 0x0010, "US", us(h))
        + element(0x0028, 0x0011, "US", us(w))
        + element(0x0028, 0x0030, "DS", b"0.1\\0.1")
        + element(0x0028, 0x0100, "US", us(8))
        + element(0x0028, 0x0101, "US", us(8))
        + element(0x0028, 0x0102, "US", us(7))
        + element(0x0028, 0x0103, "US", us(0))
        + element(0x7FE0, 0x0010, "OB", pixels)
    )
    return b"\0" * 128 + b"DICM" + meta + data


def nifti(dims, datatype, bitpix, voxels):
    """A single-file NIfTI-1 (.nii): the 348-byte header, 4 bytes of extension flag, the data."""
    h = bytearray(348)
    struct.pack_into("<i", h, 0, 348)
    dim = [len(dims)] + list(dims) + [1] * (7 - len(dims))
    struct.pack_into("<8h", h, 40, *dim)
    struct.pack_into("<h", h, 70, datatype)
    struct.pack_into("<h", h, 72, bitpix)
    struct.pack_into("<8f", h, 76, 1.0, 0.5, 0.5, 2.0, 1.0, 1.0, 1.0, 1.0)
    struct.pack_into("<f", h, 108, 352.0)  # vox_offset
    struct.pack_into("<f", h, 112, 1.0)  # scl_slope
    h[123] = 2  # xyzt_units: millimetre
    h[344:348] = b"n+1\0"
    return bytes(h) + b"\0\0\0\0" + voxels


def main():
    write("deck", "two_quads.inp", DECK)
    write("deck", "triangles.inp", TRIANGLES)
    write("deck", "three_laws.inp", (ROOT / "crates/femu-mech/tests/data/three_laws.inp").read_bytes())
    for m in ["gmsh_two_surfaces.msh", "two_regions.msh"]:
        write("gmsh", m, (ROOT / "crates/femu-mesh/tests/data" / m).read_bytes())
    write("measured_csv", "sd.csv", CSV)
    write("measured_csv", "weights.csv", CSV_WEIGHTS)
    write("measured_csv", "plain.csv", CSV_PLAIN)
    write("study", "small.toml", STUDY)
    write("study", "convergence.toml", CONVERGENCE)
    write("study", "joint_windows.toml", (ROOT / "docs/studies/joint_windows.toml").read_bytes())
    sp = speckle(16, 12)
    write("image", "grey8.png", image_bytes(sp, "PNG"))
    write("image", "grey16.png", image_bytes(sp.convert("I;16"), "PNG"))
    write("image", "grey8.tif", image_bytes(sp, "TIFF"))
    write("image", "rgb.png", image_bytes(sp.convert("RGB"), "PNG"))
    write("image", "frames.dcm", dicom(16, 12, 1))
    write("dicom", "one_frame.dcm", dicom(16, 12, 1))
    write("dicom", "two_frames.dcm", dicom(8, 6, 2))
    lab = labels(20, 16)
    write("label_image", "labels.png", image_bytes(lab, "PNG"))
    write("label_image", "labels.tif", image_bytes(lab, "TIFF"))
    vol = bytes(
        (7 if (i - 4) ** 2 + (j - 3) ** 2 < 2 else 2 if (i - 4) ** 2 + (j - 3) ** 2 < 9 else 0)
        for k in range(3)
        for j in range(6)
        for i in range(8)
    )
    write("nifti", "volume_u8.nii", nifti([8, 6, 3], 2, 8, vol))
    write("nifti", "slice_i16.nii", nifti([8, 6], 4, 16, b"".join(struct.pack("<h", v) for v in vol[:48])))


if __name__ == "__main__":
    main()
