#!/usr/bin/env python3
"""Regenerates the malformed-input corpus (deterministic). Run from this folder.

The expected outcome of each file is listed in README.md (read by tests/malformed.rs).
Fuzzer findings are added by hand as `fuzz_*` files and are not produced here.
"""
import random
import struct

random.seed(6)
TETRA_V = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
TETRA_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def w(name, data):
    if isinstance(data, str):
        data = data.encode()
    with open(name, "wb") as f:
        f.write(data)


def obj(verts=TETRA_V, faces=TETRA_F, nl="\n"):
    s = "".join(f"v {x} {y} {z}{nl}" for x, y, z in verts)
    return s + "".join(f"f {a+1} {b+1} {c+1}{nl}" for a, b, c in faces)


def ply_ascii(verts=TETRA_V, faces=TETRA_F, nv=None, nf=None, xtype="float", nl="\n"):
    nv = len(verts) if nv is None else nv
    nf = len(faces) if nf is None else nf
    h = [
        "ply",
        "format ascii 1.0",
        f"element vertex {nv}",
        f"property {xtype} x",
        f"property {xtype} y",
        f"property {xtype} z",
        f"element face {nf}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    body = [f"{x} {y} {z}" for x, y, z in verts] + [
        f"{len(f)} " + " ".join(str(i) for i in f) for f in faces
    ]
    return nl.join(h + body) + nl


def ply_bin(verts=TETRA_V, faces=TETRA_F, be=False, nv=None, nf=None, xtype="float", vfmt="f"):
    e = ">" if be else "<"
    nv = len(verts) if nv is None else nv
    nf = len(faces) if nf is None else nf
    fmt = "binary_big_endian" if be else "binary_little_endian"
    h = (
        f"ply\nformat {fmt} 1.0\nelement vertex {nv}\n"
        f"property {xtype} x\nproperty {xtype} y\nproperty {xtype} z\n"
        f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    b = b"".join(struct.pack(e + vfmt * 3, *v) for v in verts)
    b += b"".join(struct.pack(e + "B" + "i" * len(f), len(f), *f) for f in faces)
    return h + b


def stl_ascii(tris, nl="\n"):
    s = "solid t" + nl
    for t in tris:
        s += "facet normal 0 0 0" + nl + "outer loop" + nl
        s += "".join(f"vertex {x} {y} {z}{nl}" for x, y, z in t)
        s += "endloop" + nl + "endfacet" + nl
    return s + "endsolid t" + nl


def tetra_tris():
    return [tuple(TETRA_V[i] for i in f) for f in TETRA_F]


def stl_bin(tris, count=None, header=b"binary stl"):
    count = len(tris) if count is None else count
    b = header.ljust(80, b" ")[:80] + struct.pack("<I", count)
    for t in tris:
        b += struct.pack("<3f", 0, 0, 0)
        for v in t:
            b += struct.pack("<3f", *v)
        b += b"\0\0"
    return b


def off(verts=TETRA_V, faces=TETRA_F, nv=None, nf=None, nl="\n"):
    nv = len(verts) if nv is None else nv
    nf = len(faces) if nf is None else nf
    s = f"OFF{nl}{nv} {nf} 0{nl}"
    s += "".join(f"{x} {y} {z}{nl}" for x, y, z in verts)
    return s + "".join(f"{len(f)} " + " ".join(map(str, f)) + nl for f in faces)


def junk(n):
    return bytes(random.randrange(256) for _ in range(n))


def mixed(s):
    """Alternates LF and CRLF line endings."""
    out = []
    for i, line in enumerate(s.split("\n")):
        out.append(line + ("\r\n" if i % 2 else "\n"))
    return "".join(out[:-1])


BOM = b"\xef\xbb\xbf"
NANV = [(0.0, 0.0, 0.0), (1.0, float("nan"), 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
INFV = [(0.0, 0.0, 0.0), (1.0, 0.0, float("inf")), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]

# --- OBJ
w("empty.obj", b"")
w("obj_truncated_mid_vertex.obj", obj()[:30])
w("obj_truncated_mid_face.obj", obj()[:-5])
w("obj_nan_coordinate.obj", obj(verts=NANV))
w("obj_inf_coordinate.obj", obj(verts=INFV))
w("obj_index_zero.obj", obj() + "f 0 1 2\n")
w("obj_index_out_of_range.obj", obj() + "f 1 2 5\n")
w("obj_negative_index_past_start.obj", obj() + "f -1 -2 -5\n")
w("obj_face_one_vertex.obj", obj() + "f 1\n")
w("obj_face_two_vertices.obj", obj() + "f 1 2\n")
w("obj_vertices_only.obj", obj(faces=[]))
w("obj_comments_only.obj", "# nothing\n# here\n")
w("obj_binary_junk.obj", junk(700))
w("obj_not_a_number.obj", obj().replace("v 1.0 0.0 0.0", "v 1.0 abc 0.0"))
w("obj_index_overflows_i64.obj", obj() + "f 1 2 99999999999999999999999\n")
w("obj_index_past_u32.obj", obj() + "f 1 2 4294967297\n")
w("obj_vertex_w_zero.obj", obj().replace("v 1.0 0.0 0.0", "v 1.0 0.0 0.0 0.0"))
w("obj_mixed_line_endings.obj", mixed(obj()))
w("obj_cr_only_line_endings.obj", obj().replace("\n", "\r"))
w("obj_utf8_bom.obj", BOM + obj().encode())
w("obj_quads_and_relative_indices.obj",
  obj(faces=[]) + "f 1 3 2\nf -4 -3 -1\nf 1 4 3\nf 2 3 4\n")

# --- PLY ASCII
w("empty.ply", b"")
w("ply_ascii_truncated.ply", ply_ascii()[:-12])
w("ply_ascii_nan_coordinate.ply", ply_ascii(verts=NANV))
w("ply_ascii_inf_coordinate.ply", ply_ascii(verts=INFV))
w("ply_ascii_index_out_of_range.ply", ply_ascii(faces=TETRA_F[:3] + [(1, 2, 4)]))
w("ply_ascii_negative_index.ply", ply_ascii(faces=TETRA_F[:3] + [(1, 2, -1)]))
w("ply_ascii_face_two_vertices.ply", ply_ascii(faces=TETRA_F[:3] + [(1, 2)]))
w("ply_ascii_face_one_vertex.ply", ply_ascii(faces=TETRA_F[:3] + [(1,)]))
w("ply_header_only_no_end_header.ply", "ply\nformat ascii 1.0\nelement vertex 4\n")
w("ply_header_count_too_large.ply", ply_ascii(nv=100))
w("ply_header_count_too_small.ply", ply_ascii(nv=3))
w("ply_header_type_lies_uchar_holds_real.ply", ply_ascii(verts=[(0.5, 0.0, 0.0)] + TETRA_V[1:], xtype="uchar"))
w("ply_header_unknown_type.ply", ply_ascii(xtype="float128"))
w("ply_header_negative_count.ply", ply_ascii(nv=-4))
w("ply_claims_2pow31_vertices.ply", ply_ascii(nv=2**31))
w("ply_claims_2pow32_faces.ply", ply_ascii(nf=2**32))
w("ply_vertices_only.ply", ply_ascii(faces=[]))
w("ply_not_ply_magic.ply", "plx\n" + ply_ascii()[4:])
w("ply_binary_junk.ply", junk(600))
w("ply_ascii_mixed_line_endings.ply", mixed(ply_ascii()))
w("ply_ascii_utf8_bom.ply", BOM + ply_ascii().encode())
# --- PLY binary
w("ply_binary_le_valid.ply", ply_bin())
w("ply_binary_be_valid.ply", ply_bin(be=True))
w("ply_binary_le_truncated.ply", ply_bin()[:-7])
w("ply_binary_be_truncated.ply", ply_bin(be=True)[:-7])
w("ply_binary_le_nan_coordinate.ply", ply_bin(verts=NANV))
w("ply_binary_be_inf_coordinate.ply", ply_bin(verts=INFV, be=True))
w("ply_binary_le_index_out_of_range.ply", ply_bin(faces=TETRA_F[:3] + [(1, 2, 7)]))
w("ply_binary_be_negative_index.ply", ply_bin(be=True, faces=TETRA_F[:3] + [(1, 2, -3)]))
w("ply_binary_le_claims_2pow31_vertices.ply", ply_bin(nv=2**31))
w("ply_binary_be_claims_2pow31_faces.ply", ply_bin(be=True, nf=2**31))
w("ply_binary_le_type_lies_double_holds_float.ply", ply_bin(xtype="double"))
w("ply_binary_le_face_list_count_255.ply",
  ply_bin(faces=[])[:-0 or None].replace(b"element face 0", b"element face 1") + b"\xff\0\0\0\0")
w("ply_binary_le_header_then_junk.ply", ply_bin()[: ply_bin().index(b"end_header\n") + 11] + junk(90))

# --- STL
w("empty.stl", b"")
w("stl_ascii_truncated.stl", stl_ascii(tetra_tris())[:-40])
w("stl_ascii_nan_coordinate.stl", stl_ascii(tetra_tris()).replace("vertex 1.0 0.0 0.0", "vertex 1.0 nan 0.0", 1))
w("stl_ascii_inf_coordinate.stl", stl_ascii(tetra_tris()).replace("vertex 1.0 0.0 0.0", "vertex 1.0 -inf 0.0", 1))
w("stl_ascii_facet_two_vertices.stl",
  stl_ascii(tetra_tris()).replace("vertex 0.0 1.0 0.0\n", "", 1))
w("stl_ascii_facet_no_vertices.stl", "solid t\nfacet normal 0 0 1\nouter loop\nendloop\nendfacet\nendsolid t\n")
w("stl_ascii_vertices_only.stl", "solid t\nvertex 0 0 0\nvertex 1 0 0\nendsolid t\n")
w("stl_ascii_only_solid_line.stl", "solid t\n")
w("stl_ascii_mixed_line_endings.stl", mixed(stl_ascii(tetra_tris())))
w("stl_ascii_utf8_bom.stl", BOM + stl_ascii(tetra_tris()).encode())
w("stl_binary_valid.stl", stl_bin(tetra_tris()))
w("stl_binary_header_starts_with_solid.stl", stl_bin(tetra_tris(), header=b"solid exported by a tool"))
w("stl_binary_truncated.stl", stl_bin(tetra_tris())[:-20])
w("stl_binary_count_too_small.stl", stl_bin(tetra_tris(), count=2))
w("stl_binary_count_too_large.stl", stl_bin(tetra_tris(), count=12))
w("stl_binary_claims_2pow31_triangles.stl", stl_bin(tetra_tris()[:1], count=2**31))
w("stl_binary_nan_coordinate.stl", stl_bin([((0, 0, 0), (1, float("nan"), 0), (0, 1, 0))] + tetra_tris()[1:]))
w("stl_binary_inf_coordinate.stl", stl_bin([((0, 0, 0), (1, 0, float("inf")), (0, 1, 0))] + tetra_tris()[1:]))
w("stl_binary_zero_triangles.stl", stl_bin([]))
w("stl_binary_junk.stl", junk(333))
w("stl_too_short.stl", b"abcdefghij")

# --- OFF
w("empty.off", b"")
w("off_truncated.off", off()[:-9])
w("off_nan_coordinate.off", off(verts=NANV))
w("off_inf_coordinate.off", off(verts=INFV))
w("off_index_out_of_range.off", off(faces=TETRA_F[:3] + [(1, 2, 4)]))
w("off_negative_index.off", off(faces=TETRA_F[:3] + [(1, 2, -1)]))
w("off_face_two_vertices.off", off(faces=TETRA_F[:3] + [(1, 2)]))
w("off_claims_2pow31_vertices.off", off(nv=2**31))
w("off_claims_2pow31_faces.off", off(nf=2**31))
w("off_vertices_only.off", off(faces=[]))
w("off_counts_missing.off", "OFF\n")
w("off_binary_variant.off", b"OFF BINARY\n" + junk(64))
w("off_binary_junk.off", junk(500))
w("off_mixed_line_endings.off", mixed(off()))
w("off_utf8_bom.off", BOM + off().encode())
# --- other
w("unknown_extension.xyz", obj())
