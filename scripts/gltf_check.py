"""Opens `mochi export`'s `.glb` files with trimesh (run by scripts/gltf.sh) and checks each
against its own JSON chunk: one mesh, the vertex and triangle counts of its primitive, UVs
when the primitive has TEXCOORD_0, and an animation with one keyframe per morph target plus
the base, whose last keyframe gives its target the whole weight. Prints one line per file;
exit status 1 when any check fails.

    python scripts/gltf_check.py FILE.glb [FILE.glb ...]
"""

import json
import struct
import sys

import numpy as np
import trimesh


def gltf_json(path):
    with open(path, "rb") as f:
        magic, version, _ = struct.unpack("<4sII", f.read(12))
        assert magic == b"glTF" and version == 2, f"not a glTF 2.0 binary ({magic}, {version})"
        length, kind = struct.unpack("<I4s", f.read(8))
        assert kind == b"JSON", "first chunk is not JSON"
        return json.loads(f.read(length))


def check(path):
    doc = gltf_json(path)
    (primitive,) = doc["meshes"][0]["primitives"]
    accessors = doc["accessors"]
    vertices = accessors[primitive["attributes"]["POSITION"]]["count"]
    triangles = accessors[primitive["indices"]]["count"] // 3
    targets = len(primitive.get("targets", []))
    scene = trimesh.load(path, process=False)
    meshes = list(scene.geometry.values())
    assert len(meshes) == 1, f"trimesh sees {len(meshes)} meshes"
    mesh = meshes[0]
    assert mesh.vertices.shape == (vertices, 3), f"vertices {mesh.vertices.shape}, JSON {vertices}"
    assert mesh.faces.shape == (triangles, 3), f"faces {mesh.faces.shape}, JSON {triangles}"
    assert np.isfinite(mesh.vertices).all(), "a vertex is not finite"
    if "TEXCOORD_0" in primitive["attributes"]:
        uv = getattr(mesh.visual, "uv", None)
        assert uv is not None and uv.shape == (vertices, 2), "UVs lost"
    (animation,) = doc["animations"]
    (sampler,) = animation["samplers"]
    keys = accessors[sampler["input"]]["count"]
    weights = accessors[sampler["output"]]["count"]
    assert keys == targets + 1, f"{keys} keyframes for {targets} morph targets"
    assert weights == keys * targets, f"{weights} weights for {keys} keyframes"
    assert animation["channels"][0]["target"]["path"] == "weights"
    print(f"ok   {path}: trimesh opens it; {vertices} vertices, {triangles} triangles, "
          f"{targets} morph targets, {keys} keyframes")


def main():
    failed = 0
    for path in sys.argv[1:]:
        try:
            check(path)
        except Exception as e:  # every failure is reported, the others still checked
            print(f"FAIL {path}: {e}")
            failed += 1
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
