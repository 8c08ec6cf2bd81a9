//! Tests of surface assets: reading each format, repair, the errors bad assets get, and the
//! render embedding. Assets are written by the tests into temporary directories.

use std::path::{Path, PathBuf};

use base64::Engine;

use super::render::{RenderEmbedding, WEIGHT_TOLERANCE};
use super::repair::{repair, weld, RepairPolicy};
use super::{read_surface, Surface};
use crate::error::InputError;
use crate::mesh::procedural::box_tets;

/// The unit cube's corners and its 12 triangles, counter-clockwise seen from outside.
const CUBE_VERTICES: [[f64; 3]; 8] = [
    [0., 0., 0.],
    [1., 0., 0.],
    [1., 1., 0.],
    [0., 1., 0.],
    [0., 0., 1.],
    [1., 0., 1.],
    [1., 1., 1.],
    [0., 1., 1.],
];
const CUBE_TRIANGLES: [[usize; 3]; 12] = [
    [0, 2, 1],
    [0, 3, 2],
    [4, 5, 6],
    [4, 6, 7],
    [0, 1, 5],
    [0, 5, 4],
    [1, 2, 6],
    [1, 6, 5],
    [2, 3, 7],
    [2, 7, 6],
    [3, 0, 4],
    [3, 4, 7],
];

/// OBJ text of triangles over vertices (shifted by `offset`), 1-based.
fn obj_text(vertices: &[[f64; 3]], triangles: &[[usize; 3]]) -> String {
    let mut s = String::new();
    for v in vertices {
        s += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    for t in triangles {
        s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// The error of reading and repairing `path` with the default (strict) policy.
fn strict_error(path: &Path) -> InputError {
    let result = read_surface(path).and_then(|s| repair(&s, path, &RepairPolicy::default()));
    let error = result.expect_err("a bad asset must be refused");
    assert_eq!(error.file, path, "the error names the file: {error}");
    error
}

fn assert_mentions(error: &InputError, words: &str) {
    let text = error.to_string();
    assert!(text.contains(words), "`{text}` should mention `{words}`");
}

/// Little-endian bytes of a binary STL of `triangles`.
fn binary_stl(vertices: &[[f64; 3]], triangles: &[[usize; 3]]) -> Vec<u8> {
    let mut bytes = vec![0u8; 80];
    bytes.extend((triangles.len() as u32).to_le_bytes());
    for t in triangles {
        bytes.extend([0f32; 3].iter().flat_map(|c| c.to_le_bytes()));
        for &v in t {
            bytes.extend(vertices[v].iter().flat_map(|&c| (c as f32).to_le_bytes()));
        }
        bytes.extend([0u8; 2]);
    }
    bytes
}

/// A glTF document of the cube (positions and indices in one buffer) under a node named
/// `jelly` with `transform` (glTF node properties), and the buffer's bytes.
fn gltf_cube(transform: &str) -> (String, Vec<u8>) {
    let mut buffer: Vec<u8> = CUBE_VERTICES
        .iter()
        .flatten()
        .flat_map(|&c| (c as f32).to_le_bytes())
        .collect();
    buffer.extend(CUBE_TRIANGLES.iter().flatten().flat_map(|&i| (i as u16).to_le_bytes()));
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"name":"jelly","mesh":0{transform}}}],
        "meshes":[{{"name":"cube","primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
        "buffers":[{{"byteLength":{len}BUFFER_URI}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":96}},{{"buffer":0,"byteOffset":96,"byteLength":72}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":8,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}},
                     {{"bufferView":1,"componentType":5123,"count":36,"type":"SCALAR"}}]}}"#,
        len = buffer.len()
    );
    (json, buffer)
}

/// A GLB container of `json` and `bin`.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

#[test]
fn obj_cube_with_seams_reads_and_repairs_closed_and_outward() {
    // Each face has its own UVs and normal, so the asset splits every corner: 24 render
    // vertices that weld into 8.
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("o jelly\n");
    for v in CUBE_VERTICES {
        text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    text += "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 0 -1\n";
    // Quads, given inward (clockwise from outside): repair flips them.
    let quads = [
        [0, 1, 2, 3],
        [4, 7, 6, 5],
        [0, 4, 5, 1],
        [1, 5, 6, 2],
        [2, 6, 7, 3],
        [3, 7, 4, 0],
    ];
    for (k, q) in quads.iter().enumerate() {
        let n = 1 + k % 2;
        text += &format!(
            "f {}/1/{n} {}/2/{n} {}/3/{n} {}/4/{n}\n",
            q[0] + 1,
            q[1] + 1,
            q[2] + 1,
            q[3] + 1
        );
    }
    let path = write(&dir, "cube.obj", text.as_bytes());
    let surface = read_surface(&path).unwrap();
    assert_eq!(surface.triangles.len(), 12);
    assert!(surface.positions.len() > 8);
    assert_eq!(surface.uvs.as_ref().map(Vec::len), Some(surface.positions.len()));
    assert_eq!(surface.normals.as_ref().map(Vec::len), Some(surface.positions.len()));
    assert_eq!(surface.parts[0].name.as_deref(), Some("jelly"));
    let repaired = repair(&surface, &path, &RepairPolicy::default()).unwrap();
    let r = &repaired.report;
    assert_eq!(
        (r.welded_vertices, r.boundary_edges, r.holes, r.components),
        (8, 0, 0, 1)
    );
    assert_eq!(r.flipped_triangles, 12, "inward faces are turned outward");
    assert!((r.volume - 1.0).abs() < 1e-12, "{}", r.volume);
    assert_eq!(repaired.welded_of.len(), surface.positions.len());
}

#[test]
fn mixed_orientations_are_made_consistent() {
    let mut triangles = CUBE_TRIANGLES.to_vec();
    for t in triangles.iter_mut().step_by(3) {
        t.swap(0, 1);
    }
    let surface = Surface {
        positions: CUBE_VERTICES.to_vec(),
        triangles,
        parts: Vec::new(),
        ..Surface::default()
    };
    let repaired = repair(&surface, Path::new("mixed"), &RepairPolicy::default()).unwrap();
    assert_eq!(repaired.report.flipped_triangles, 4);
    let mut got = repaired.triangles.clone();
    let mut want = CUBE_TRIANGLES.to_vec();
    let canonical = |t: &mut [usize; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        t.rotate_left(k);
    };
    got.iter_mut().for_each(canonical);
    want.iter_mut().for_each(canonical);
    got.sort_unstable();
    want.sort_unstable();
    assert_eq!(got, want);
}

#[test]
fn weld_joins_points_within_the_tolerance_only() {
    let points = [
        [0.0, 0.0, 0.0],
        [1e-9, 0.0, 0.0],
        [0.0, 2e-3, 0.0],
        [5.0, 5.0, 5.0],
        [5.0, 5.0, 5.0 + 5e-10],
    ];
    let (of, welded) = weld(&points, 1e-6);
    assert_eq!(of, vec![0, 0, 1, 2, 2]);
    assert_eq!(welded.len(), 3);
    let (of, _) = weld(&points, 0.0);
    assert_eq!(of, vec![0, 1, 2, 3, 4]);
}

#[test]
fn gltf_and_glb_apply_node_transforms_and_names() {
    let dir = tempfile::tempdir().unwrap();
    // Mirrored in x and moved: the winding is flipped to stay outward.
    let (json, buffer) = gltf_cube(r#","scale":[-2,1,1],"translation":[10,0,0]"#);
    let uri = format!(
        r#","uri":"data:application/octet-stream;base64,{}""#,
        base64::engine::general_purpose::STANDARD.encode(&buffer)
    );
    let gltf = write(&dir, "cube.gltf", json.replace("BUFFER_URI", &uri).as_bytes());
    let glb_path = write(&dir, "cube.glb", &glb(&json.replace("BUFFER_URI", ""), &buffer));
    for path in [gltf, glb_path] {
        let surface = read_surface(&path).unwrap();
        assert_eq!(surface.parts.len(), 1);
        assert_eq!(surface.parts[0].name.as_deref(), Some("jelly"));
        let (lo, hi) = surface.bounds();
        assert_eq!((lo, hi), ([8.0, 0.0, 0.0], [10.0, 1.0, 1.0]), "{path:?}");
        let repaired = repair(&surface, &path, &RepairPolicy::default()).unwrap();
        assert_eq!(
            repaired.report.flipped_triangles, 0,
            "mirroring keeps the faces outward"
        );
        assert!((repaired.report.volume - 2.0).abs() < 1e-9);
    }
}

#[test]
fn binary_and_ascii_stl_read_the_same_cube() {
    let dir = tempfile::tempdir().unwrap();
    let binary = write(&dir, "cube.stl", &binary_stl(&CUBE_VERTICES, &CUBE_TRIANGLES));
    // A tab after `solid`, as some writers put it.
    let mut ascii = String::from("solid\tcube\n");
    for t in CUBE_TRIANGLES {
        ascii += "facet normal 0 0 0\nouter loop\n";
        for v in t {
            let p = CUBE_VERTICES[v];
            ascii += &format!("vertex {} {} {}\n", p[0], p[1], p[2]);
        }
        ascii += "endloop\nendfacet\n";
    }
    ascii += "endsolid cube\n";
    let ascii = write(&dir, "ascii.stl", ascii.as_bytes());
    for path in [binary, ascii] {
        let surface = read_surface(&path).unwrap();
        assert_eq!((surface.positions.len(), surface.triangles.len()), (8, 12), "{path:?}");
        let repaired = repair(&surface, &path, &RepairPolicy::default()).unwrap();
        assert!((repaired.report.volume - 1.0).abs() < 1e-9);
    }
}

// --- Bad assets: each refused with an error naming the file and the defect.

#[test]
fn an_empty_asset_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(&dir, "empty.obj", b"# nothing here\nv 0 0 0\n");
    assert_mentions(&strict_error(&path), "empty surface");
}

#[test]
fn an_asset_of_degenerate_triangles_only_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // Collinear points, and a triangle whose corners weld into one.
    let text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 0 1 1e-12\nf 1 2 3\nf 4 5 4\n";
    let path = write(&dir, "flat.obj", text.as_bytes());
    assert_mentions(&strict_error(&path), "all 2 triangles have zero area");
}

#[test]
fn a_non_finite_coordinate_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut vertices = CUBE_VERTICES;
    vertices[5][1] = f64::NAN;
    let path = write(&dir, "nan.obj", obj_text(&vertices, &CUBE_TRIANGLES).as_bytes());
    assert_mentions(&strict_error(&path), "vertex 5 has a coordinate that is not finite");
    let path = write(
        &dir,
        "inf.stl",
        &binary_stl(&[[f64::INFINITY, 0.0, 0.0]; 3], &[[0, 1, 2]]),
    );
    assert_mentions(&strict_error(&path), "not finite");
}

#[test]
fn an_open_surface_is_refused_and_its_hole_counted() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "open.obj",
        obj_text(&CUBE_VERTICES, &CUBE_TRIANGLES[2..]).as_bytes(),
    );
    assert_mentions(&strict_error(&path), "open surface: 1 hole(s) bounded by 4 edge(s)");
    // Accepted, it is a warning and the report keeps the count.
    let surface = read_surface(&path).unwrap();
    let repaired = repair(&surface, &path, &RepairPolicy::accepting_defects()).unwrap();
    assert_eq!((repaired.report.holes, repaired.report.boundary_edges), (1, 4));
    assert_eq!(repaired.warnings.len(), 1);
}

#[test]
fn a_non_manifold_surface_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // A fin on the edge 0-1 of the cube: three triangles share that edge.
    let mut vertices = CUBE_VERTICES.to_vec();
    vertices.push([0.5, -1.0, -1.0]);
    let mut triangles = CUBE_TRIANGLES.to_vec();
    triangles.push([0, 1, 8]);
    let path = write(&dir, "fin.obj", obj_text(&vertices, &triangles).as_bytes());
    let error = read_surface(&path)
        .and_then(|s| {
            let policy = RepairPolicy {
                open: true,
                ..RepairPolicy::default()
            };
            repair(&s, &path, &policy)
        })
        .unwrap_err();
    assert_mentions(&error, "non-manifold surface: 1 edge(s)");
}

#[test]
fn a_self_intersecting_surface_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // Two closed cubes, the second pushed halfway into the first.
    let mut vertices = CUBE_VERTICES.to_vec();
    vertices.extend(CUBE_VERTICES.iter().map(|p| [p[0] + 0.5, p[1] + 0.25, p[2] + 0.3]));
    let mut triangles = CUBE_TRIANGLES.to_vec();
    triangles.extend(CUBE_TRIANGLES.iter().map(|t| t.map(|v| v + 8)));
    let path = write(&dir, "overlap.obj", obj_text(&vertices, &triangles).as_bytes());
    assert_mentions(&strict_error(&path), "self-intersecting surface");
    // Apart, the same two cubes are fine: two components, no crossing.
    let apart: Vec<[f64; 3]> = vertices
        .iter()
        .enumerate()
        .map(|(i, p)| if i >= 8 { [p[0] + 3.0, p[1], p[2]] } else { *p })
        .collect();
    let path = write(&dir, "apart.obj", obj_text(&apart, &triangles).as_bytes());
    let repaired = repair(&read_surface(&path).unwrap(), &path, &RepairPolicy::default()).unwrap();
    assert_eq!((repaired.report.components, repaired.report.self_intersections), (2, 0));
}

#[test]
fn truncated_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let stl = binary_stl(&CUBE_VERTICES, &CUBE_TRIANGLES);
    let path = write(&dir, "cut.stl", &stl[..stl.len() - 70]);
    assert_mentions(&strict_error(&path), "cut.stl");
    let (json, buffer) = gltf_cube("");
    let whole = glb(&json.replace("BUFFER_URI", ""), &buffer);
    let path = write(&dir, "cut.glb", &whole[..whole.len() - 40]);
    let error = strict_error(&path);
    assert!(
        error.to_string().contains("truncated") || error.to_string().contains("not a readable glTF"),
        "{error}"
    );
    // A .gltf whose buffer file is missing or short.
    let path = write(
        &dir,
        "missing.gltf",
        json.replace("BUFFER_URI", r#","uri":"missing.bin""#).as_bytes(),
    );
    assert_mentions(&strict_error(&path), "missing.bin");
    write(&dir, "short.bin", &buffer[..100]);
    let path = write(
        &dir,
        "short.gltf",
        json.replace("BUFFER_URI", r#","uri":"short.bin""#).as_bytes(),
    );
    assert_mentions(&strict_error(&path), "truncated: 100 bytes");
}

#[test]
fn wrong_extensions_and_unreadable_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (json, buffer) = gltf_cube("");
    let path = write(&dir, "cube.obj", &glb(&json.replace("BUFFER_URI", ""), &buffer));
    assert_mentions(&strict_error(&path), "the extension says Obj but the contents are Glb");
    let path = write(&dir, "cube.fbx", b"Kaydara FBX Binary");
    assert_mentions(&strict_error(&path), "unknown surface format `.fbx`");
    let path = dir.path().join("absent.obj");
    assert_mentions(&strict_error(&path), "cannot read");
    let path = write(&dir, "garbage.gltf", b"{ \"asset\": ");
    assert_mentions(&strict_error(&path), "not a readable glTF 2.0 file");
}

#[test]
fn out_of_range_references_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(&dir, "range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    assert_mentions(&strict_error(&path), "range.obj:4: vertex reference 4 is out of range");
    let (json, buffer) = gltf_cube("");
    let mut bad = buffer.clone();
    bad[96..98].copy_from_slice(&9u16.to_le_bytes());
    let path = write(&dir, "range.glb", &glb(&json.replace("BUFFER_URI", ""), &bad));
    assert_mentions(&strict_error(&path), "index 9 is out of range");
}

// --- The render embedding.

/// Render vertices (inside a tet mesh and a little outside it) keep their rest positions (the
/// ones inside within rounding, the others within their distance, which stays the offset
/// given) and never leave their tets' convex hull by more than the stated tolerance.
#[test]
fn render_vertices_ride_inside_their_tets() {
    let sim = box_tets([0.0, 0.0, 0.0], [1.0, 0.5, 0.5], [5, 3, 3]).unwrap();
    // A sphere-ish cloud inside the box, and points just outside its faces.
    let mut positions = Vec::new();
    for i in 0..200 {
        let t = i as f64 * 0.618_033_988_749_895;
        let (a, b) = (
            t.fract() * std::f64::consts::TAU,
            (t * 1.7).fract() * std::f64::consts::PI,
        );
        let r = 0.05 + 0.18 * (t * 3.1).fract();
        positions.push([
            0.5 + 2.0 * r * b.sin() * a.cos(),
            0.25 + r * b.sin() * a.sin(),
            0.25 + r * b.cos(),
        ]);
    }
    let outside = [[1.002, 0.2, 0.2], [0.3, -0.001, 0.4], [0.5, 0.25, 0.5004]];
    positions.extend(outside);
    let surface = Surface {
        triangles: (0..positions.len() - 2).map(|i| [i, i + 1, i + 2]).collect(),
        positions,
        ..Surface::default()
    };
    let render = RenderEmbedding::new(&surface, &sim).unwrap();
    assert!(
        (render.max_distance() - 0.002).abs() < 1e-12,
        "{}",
        render.max_distance()
    );
    let rest = render.positions(&sim.rest);
    for (i, (p, q)) in surface.positions.iter().zip(rest.chunks(3)).enumerate() {
        let a = &render.embedding.anchors[i];
        let error = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt();
        assert!(error <= a.distance + 1e-12, "vertex {i}: {error} > {}", a.distance);
        assert!((a.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(
            a.weights
                .iter()
                .all(|w| (-WEIGHT_TOLERANCE..=1.0 + WEIGHT_TOLERANCE).contains(w)),
            "{a:?}"
        );
        let Elements::Tets(tets) = &sim.elements else {
            unreachable!()
        };
        let mut tet = tets[render.tets[i]];
        tet.sort_unstable();
        let mut named = a.vertices;
        named.sort_unstable();
        assert_eq!(tet, named, "vertex {i}: the tet index names the anchor's tet");
    }
    // The archive holds the same numbers.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("render.npz");
    render.write_npz(&path).unwrap();
    let mut npz = crate::npz::NpzFile::open(&path).unwrap();
    for name in ["positions", "triangles", "tet", "tet_vertices", "weights", "distance"] {
        assert!(npz.has(name), "{name}");
    }
    assert!(!npz.has("uvs"));
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "no temporary file left"
    );
}

use crate::mesh::Elements;

#[test]
fn render_archives_read_back_as_written_and_bad_ones_are_refused() {
    let sim = box_tets([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2, 2, 2]).unwrap();
    let positions = vec![[0.2, 0.3, 0.4], [0.8, 0.1, 0.5], [0.5, 0.9, 0.2], [1.1, 0.5, 0.5]];
    let surface = Surface {
        positions,
        triangles: vec![[0, 1, 2], [1, 3, 2]],
        normals: Some(vec![[0.0, 0.0, 1.0]; 4]),
        uvs: Some(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),
        ..Surface::default()
    };
    let render = RenderEmbedding::new(&surface, &sim).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.render.npz");
    render.write_npz(&path).unwrap();
    let back = RenderEmbedding::read_npz(&path).unwrap();
    assert_eq!(back.surface.parts.len(), 1);
    let whole = RenderEmbedding {
        surface: Surface {
            parts: back.surface.parts.clone(),
            ..render.surface.clone()
        },
        ..render.clone()
    };
    assert_eq!(back, whole);
    assert_eq!(RenderEmbedding::read_for(&path, &sim).unwrap(), back);
    let other = box_tets([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2, 2, 3]).unwrap();
    let e = RenderEmbedding::read_for(&path, &other).unwrap_err().to_string();
    assert!(
        e.contains("sim_vertices") && e.contains("made for a mesh of 27 vertices"),
        "{e}"
    );
    let refused = |edit: &dyn Fn(&mut RenderEmbedding)| {
        let mut bad = render.clone();
        edit(&mut bad);
        bad.write_npz(&path).unwrap();
        RenderEmbedding::read_npz(&path).unwrap_err().to_string()
    };
    let e = refused(&|r| r.embedding.anchors[1].weights[0] = 1.5);
    assert!(e.contains("a.render.npz") && e.contains("weights"), "{e}");
    let e = refused(&|r| r.sim_size.0 = 3);
    assert!(e.contains("tet_vertices") && e.contains("3 simulation vertices"), "{e}");
    let e = refused(&|r| r.surface.triangles[1][2] = 4);
    assert!(e.contains("triangles") && e.contains("4 vertices"), "{e}");
    let e = refused(&|r| r.sim_size.1 = 0);
    assert!(e.contains("`tet`") || e.contains("tet"), "{e}");
}
