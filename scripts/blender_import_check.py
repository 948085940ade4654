"""Imports pnet's PLY frames into Blender, headless, and checks what arrived.

    blender -b --factory-startup --python scripts/blender_import_check.py -- FRAME.ply [FRAME.ply ...]

For each file: imports it with Blender's PLY importer (bpy.ops.import_mesh.ply, Blender 3.x;
bpy.ops.wm.ply_import from 4.0), then compares the vertex count (and, for a mesh frame, the face
count) with the PLY header, and the first vertex's position with the file's first record. Prints one
line per file and exits 1 if any check fails (Blender's own exit status is 0 even when a script fails,
so the script exits the process itself).
"""
import struct
import sys

import bpy


def header(path):
    """(vertex count, face count, vertex property names, header length in bytes)."""
    with open(path, "rb") as f:
        data = f.read(4096)
    end = data.index(b"end_header\n") + len(b"end_header\n")
    vertices = faces = 0
    props, element = [], None
    for line in data[:end].decode("ascii").splitlines():
        words = line.split()
        if words[:1] == ["element"]:
            element = words[1]
            if element == "vertex":
                vertices = int(words[2])
            elif element == "face":
                faces = int(words[2])
        elif words[:1] == ["property"] and element == "vertex":
            props.append((words[-1], words[1]))
    return vertices, faces, props, end


def first_position(path, props, start):
    sizes = {"double": ("d", 8), "float": ("f", 4), "int": ("i", 4), "uchar": ("B", 1)}
    fmt = "<" + "".join(sizes[t][0] for _, t in props)
    with open(path, "rb") as f:
        f.seek(start)
        record = struct.unpack(fmt, f.read(struct.calcsize(fmt)))
    values = dict(zip([n for n, _ in props], record))
    return values["x"], values["y"], values["z"]


def main(paths):
    failed = 0
    for path in paths:
        bpy.ops.object.select_all(action="SELECT")
        bpy.ops.object.delete()
        if bpy.app.version >= (4, 0, 0):
            bpy.ops.wm.ply_import(filepath=path)
        else:
            bpy.ops.import_mesh.ply(filepath=path)
        objects = [o for o in bpy.context.scene.objects if o.type == "MESH"]
        vertices, faces, props, start = header(path)
        mesh = objects[0].data if objects else None
        got_v = len(mesh.vertices) if mesh else 0
        got_f = len(mesh.polygons) if mesh else 0
        expected = first_position(path, props, start)
        got = tuple(mesh.vertices[0].co) if got_v else (float("nan"),) * 3
        ok = got_v == vertices and got_f == faces and all(abs(a - b) < 1e-5 for a, b in zip(got, expected))
        failed += not ok
        print(f"{'ok' if ok else 'FAILED'}: {path}: {got_v} vertices (header {vertices}), {got_f} faces "
              f"(header {faces}), first vertex {tuple(round(c, 6) for c in got)} (file {tuple(round(c, 6) for c in expected)})")
    sys.stdout.flush()
    return 1 if failed else 0


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    sys.exit(main(argv))
