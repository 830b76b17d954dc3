#!/usr/bin/env python3
"""Writes the seed corpus fuzz/corpus/<target>/: a few tiny valid inputs per fuzz target.

Run from anywhere: python3 fuzz/make_corpus.py. The files are committed; this script documents
how the binary ones were made and regenerates them after a change of input layout.
"""
import base64
import io
import json
import os
import struct
import zipfile

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")

# A tetrahedron: 4 vertices, 4 outward-facing triangles.
V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def put(target, name, data):
    folder = os.path.join(ROOT, target)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)


def obj():
    put("fuzz_mesh_obj", "tetra.obj",
        "".join(f"v {x} {y} {z}\n" for x, y, z in V) +
        "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in F))
    put("fuzz_mesh_obj", "quad_slashes_negative.obj",
        "# quad\no q\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
        "g side\nusemtl m\nf -4/1/1 -3/1/1 -2/1/1 -1/1/1\nf 1//1 3//1 2//1\n")


def stl():
    text = "solid t\n"
    for a, b, c in F:
        text += " facet normal 0 0 0\n  outer loop\n"
        for i in (a, b, c):
            text += "   vertex %g %g %g\n" % V[i]
        text += "  endloop\n endfacet\n"
    put("fuzz_mesh_stl", "tetra_ascii.stl", text + "endsolid t\n")
    binary = b"binary tetra".ljust(80, b" ") + struct.pack("<I", len(F))
    for a, b, c in F:
        binary += struct.pack("<3f", 0, 0, 0)  # normals are ignored
        for i in (a, b, c):
            binary += struct.pack("<3f", *V[i])
        binary += b"\0\0"
    put("fuzz_mesh_stl", "tetra_binary.stl", binary)


def ply():
    header = ("ply\nformat {} 1.0\ncomment seed\nelement vertex 4\nproperty float x\n"
              "property float y\nproperty float z\nelement face 4\n"
              "property list uchar int vertex_indices\nend_header\n")
    put("fuzz_mesh_ply", "tetra_ascii.ply", header.format("ascii") +
        "".join("%g %g %g\n" % v for v in V) + "".join("3 %d %d %d\n" % f for f in F))
    body = b"".join(struct.pack("<3f", *v) for v in V)
    body += b"".join(struct.pack("<B3i", 3, *f) for f in F)
    put("fuzz_mesh_ply", "tetra_binary_le.ply",
        header.format("binary_little_endian").encode() + body)


def off():
    put("fuzz_mesh_off", "tetra.off", "OFF\n# seed\n4 4 0\n" +
        "".join("%g %g %g\n" % v for v in V) + "".join("3 %d %d %d\n" % f for f in F))
    put("fuzz_mesh_off", "quad.off", "OFF 4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")


def gltf_parts():
    positions = b"".join(struct.pack("<3f", *v) for v in V)
    indices = b"".join(struct.pack("<3H", *f) for f in F)
    buffer = positions + indices
    document = {
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(buffer)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 1]},
                      {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}],
    }
    return document, buffer


def gltf():
    document, buffer = gltf_parts()
    document["buffers"][0]["uri"] = ("data:application/octet-stream;base64," +
                                     base64.b64encode(buffer).decode())
    put("fuzz_mesh_gltf", "tetra.gltf", json.dumps(document, indent=1))


def glb():
    document, buffer = gltf_parts()
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    buffer += b"\0" * (-len(buffer) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text
    chunks += struct.pack("<I4s", len(buffer), b"BIN\0") + buffer
    put("fuzz_mesh_glb", "tetra.glb", struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)


def three_mf():
    model = ('<?xml version="1.0" encoding="UTF-8"?>\n<model unit="millimeter" '
             'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
             '<resources><object id="1" type="model"><mesh><vertices>' +
             "".join('<vertex x="%g" y="%g" z="%g"/>' % v for v in V) + "</vertices><triangles>" +
             "".join('<triangle v1="%d" v2="%d" v3="%d"/>' % f for f in F) +
             '</triangles></mesh></object></resources><build><item objectid="1"/></build></model>')
    types = ('<?xml version="1.0" encoding="UTF-8"?><Types xmlns="http://schemas.openxmlformats.org/'
             'package/2006/content-types"><Default Extension="rels" ContentType="application/'
             'vnd.openxmlformats-package.relationships+xml"/><Default Extension="model" '
             'ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/></Types>')
    rels = ('<?xml version="1.0" encoding="UTF-8"?><Relationships xmlns="http://schemas.'
            'openxmlformats.org/package/2006/relationships"><Relationship Target="/3D/3dmodel.model"'
            ' Id="rel0" Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>'
            '</Relationships>')
    data = io.BytesIO()
    with zipfile.ZipFile(data, "w", zipfile.ZIP_STORED) as z:
        for name, text in (("[Content_Types].xml", types), ("_rels/.rels", rels),
                           ("3D/3dmodel.model", model)):
            info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))
            z.writestr(info, text)
    put("fuzz_mesh_3mf", "tetra.3mf", data.getvalue())


def field():
    # fuzz_field input: byte 0 = sidecar length / 4, the sidecar, then the .npy file.
    def npy(dtype, shape, fortran, values):
        header = "{'descr': '%s', 'fortran_order': %s, 'shape': (%d, %d, %d), }" % (
            dtype, fortran, *shape)
        header += " " * (-(10 + len(header) + 1) % 64) + "\n"
        data = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode()
        code = "<f" if dtype == "<f4" else "<d"
        return data + b"".join(struct.pack(code, v) for v in values)

    def entry(sidecar, array):
        text = json.dumps(sidecar).encode()
        text += b" " * (-len(text) % 4)
        return bytes([len(text) // 4]) + text + array

    sidecar = {"origin": [0, 0, 0], "voxel_size": 0.5, "dims": [2, 2, 2]}
    values = [-0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.25]
    put("fuzz_field", "f4_fortran", entry(sidecar, npy("<f4", (2, 2, 2), "True", values)))
    put("fuzz_field", "f8_c_order", entry({"origin": [1, 2, 3], "voxel_size": 2},
                                          npy("<f8", (2, 1, 3), "False", values[:6])))


def voxelize():
    # fuzz_voxelize input: 4 option bytes, then triangles of nine little-endian doubles.
    def triangles(faces, points):
        return b"".join(struct.pack("<9d", *points[a], *points[b], *points[c])
                        for a, b, c in faces)
    put("fuzz_voxelize", "tetra_surface", bytes([15, 0x00, 1, 0]) + triangles(F, V))
    put("fuzz_voxelize", "tetra_solid_winding", bytes([7, 0x06, 0, 3]) + triangles(F, V))
    put("fuzz_voxelize", "tetra_filled_pef_halfopen", bytes([31, 0x33, 2, 1]) + triangles(F, V))
    flat = [(0, 0, 0), (1e-300, 0, 0), (0, 1e300, 0), (0, 0, 0)]
    put("fuzz_voxelize", "degenerate_extremes", bytes([3, 0x01, 3, 2]) +
        triangles([(0, 1, 2), (0, 3, 3)], flat))


for make in (obj, stl, ply, off, gltf, glb, three_mf, field, voxelize):
    make()
