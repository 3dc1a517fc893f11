#!/usr/bin/env python3
"""Converts a PLY mesh (ascii or binary, vertex x/y/z + face vertex index lists) to OBJ.

Usage: ply_to_obj.py INPUT.ply OUTPUT.obj [COMMENT]
Other vertex/face properties are skipped. Exits non-zero with a message on malformed input.
"""
import struct
import sys

TYPES = {
    "char": "b", "int8": "b", "uchar": "B", "uint8": "B",
    "short": "h", "int16": "h", "ushort": "H", "uint16": "H",
    "int": "i", "int32": "i", "uint": "I", "uint32": "I",
    "float": "f", "float32": "f", "double": "d", "float64": "d",
}


def fail(msg):
    sys.exit(f"ply_to_obj: {msg}")


def read_header(f):
    if f.readline().strip() != b"ply":
        fail("not a PLY file")
    fmt, elements = None, []
    while True:
        line = f.readline()
        if not line:
            fail("header does not end")
        words = line.decode("ascii", "replace").split()
        if not words:
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            if not elements:
                fail("property before element")
            elements[-1][2].append(words[1:])
        elif words[0] == "end_header":
            break
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        fail(f"unsupported format {fmt}")
    return fmt, elements


def main():
    if len(sys.argv) < 3:
        fail("usage: ply_to_obj.py INPUT.ply OUTPUT.obj [COMMENT]")
    with open(sys.argv[1], "rb") as f:
        fmt, elements = read_header(f)
        endian = ">" if fmt == "binary_big_endian" else "<"
        tokens = iter(f.read().split()) if fmt == "ascii" else None
        data = None if fmt == "ascii" else f.read()
        pos = 0

        def scalar(t):
            nonlocal pos
            if tokens is not None:
                v = next(tokens)
                return float(v) if TYPES[t] in "fd" else int(v)
            code = endian + TYPES[t]
            v = struct.unpack_from(code, data, pos)[0]
            pos += struct.calcsize(code)
            return v

        vertices, faces = [], []
        for name, count, props in elements:
            for _ in range(count):
                values = {}
                for p in props:
                    if p[0] == "list":
                        n = scalar(p[1])
                        values[p[3]] = [scalar(p[2]) for _ in range(n)]
                    else:
                        values[p[1]] = scalar(p[0])
                if name == "vertex":
                    vertices.append((values["x"], values["y"], values["z"]))
                elif name == "face":
                    idx = values.get("vertex_indices", values.get("vertex_index"))
                    if idx is None:
                        fail("face without vertex_indices")
                    faces.append(idx)
    with open(sys.argv[2], "w") as out:
        if len(sys.argv) > 3:
            out.write(f"# {sys.argv[3]}\n")
        out.write(f"# {len(vertices)} vertices, {len(faces)} faces\n")
        for x, y, z in vertices:
            out.write(f"v {x:.9g} {y:.9g} {z:.9g}\n")
        for idx in faces:
            for i in idx:
                if not 0 <= i < len(vertices):
                    fail(f"face index {i} out of range")
            out.write("f " + " ".join(str(i + 1) for i in idx) + "\n")


if __name__ == "__main__":
    main()
