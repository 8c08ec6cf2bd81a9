//! Tests of OBJ files and PNG previews.

use super::*;
use std::fs::File;

/// Two unit cubes side by side along x, six tets each around the cube diagonal
/// (conforming at the shared face): 12 vertices, all on the surface.
fn two_cube_tets() -> Mesh {
    let mut rest = Vec::new();
    for z in 0..2 {
        for y in 0..2 {
            for x in 0..3 {
                rest.extend_from_slice(&[x as f64, y as f64, z as f64]);
            }
        }
    }
    let id = |x: usize, y: usize, z: usize| x + 3 * y + 6 * z;
    let mut tets = Vec::new();
    for cx in 0..2 {
        let c = |dx: usize, dy: usize, dz: usize| id(cx + dx, dy, dz);
        // Six tets around the diagonal c(0,0,0)-c(1,1,1).
        let (a, b) = (c(0, 0, 0), c(1, 1, 1));
        let ring = [c(1, 0, 0), c(1, 1, 0), c(0, 1, 0), c(0, 1, 1), c(0, 0, 1), c(1, 0, 1)];
        for k in 0..6 {
            tets.push([a, ring[k], ring[(k + 1) % 6], b]);
        }
    }
    let mut mesh = Mesh {
        dim: 3,
        rest,
        elements: Elements::Tets(tets),
        attributes: None,
    };
    orient_positive(&mut mesh);
    mesh
}

/// Swaps two vertices of negatively oriented tets.
fn orient_positive(mesh: &mut Mesh) {
    let rest = mesh.rest.clone();
    if let Elements::Tets(tets) = &mut mesh.elements {
        for t in tets {
            let p = t.map(|v| point(&rest, 3, v));
            let vol = dot(sub3(p[1], p[0]), cross(sub3(p[2], p[0]), sub3(p[3], p[0])));
            if vol < 0.0 {
                t.swap(2, 3);
            }
        }
    }
}

/// One tet split into four at an interior point (vertex 4).
fn split_tet() -> Mesh {
    let rest = vec![
        0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.25, 0.25, 0.25,
    ];
    let mut mesh = Mesh {
        dim: 3,
        rest,
        elements: Elements::Tets(vec![[4, 1, 2, 3], [0, 4, 2, 3], [0, 1, 4, 3], [0, 1, 2, 4]]),
        attributes: None,
    };
    orient_positive(&mut mesh);
    mesh
}

fn cloth(n: usize) -> Mesh {
    let mut rest = Vec::new();
    for j in 0..n {
        for i in 0..n {
            rest.extend_from_slice(&[i as f64 / (n - 1) as f64, 0.0, j as f64 / (n - 1) as f64]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = j * n + i;
            tris.push([v, v + 1, v + n + 1]);
            tris.push([v, v + n + 1, v + n]);
        }
    }
    Mesh {
        dim: 3,
        rest,
        elements: Elements::Shell(tris),
        attributes: None,
    }
}

/// Cloth hanging from its first row, bent down by a sine.
fn drape(mesh: &Mesh, amount: f64) -> Vec<f64> {
    let mut x = mesh.rest.clone();
    for p in x.chunks_exact_mut(3) {
        let z = p[2];
        p[1] = -amount * z * (1.0 + 0.3 * (6.0 * p[0]).sin());
        p[2] = z * (1.0 - 0.5 * amount);
    }
    x
}

fn rods() -> Mesh {
    let mut rest = Vec::new();
    let mut strands = Vec::new();
    for r in 0..4 {
        let mut strand = Vec::new();
        for k in 0..10 {
            strand.push(rest.len() / 3);
            let a = k as f64 * 0.3;
            rest.extend_from_slice(&[r as f64 * 0.5 + 0.2 * a.sin(), -(k as f64) * 0.2, 0.1 * a.cos()]);
        }
        strands.push(strand);
    }
    Mesh {
        dim: 3,
        rest,
        elements: Elements::Rods(strands),
        attributes: None,
    }
}

fn plate2d() -> Mesh {
    let (nx, ny) = (9, 3);
    let mut rest = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            rest.extend_from_slice(&[i as f64 * 0.5, j as f64 * 0.5]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let v = j * nx + i;
            tris.push([v, v + 1, v + nx + 1]);
            tris.push([v, v + nx + 1, v + nx]);
        }
    }
    Mesh {
        dim: 2,
        rest,
        elements: Elements::Triangles(tris),
        attributes: None,
    }
}

/// Decodes a PNG: (width, height, pixels as RGB).
fn decode(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    let pixels = buf[..info.buffer_size()]
        .chunks(ch)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    (info.width, info.height, pixels)
}

/// Renders and checks size and that a good share of pixels differs from the background.
fn check_render(name: &str, mesh: &Mesh, frames: &[&[f64]], opts: &RenderOptions) -> Vec<[u8; 3]> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    render_png(&path, mesh, frames, opts).unwrap();
    let (w, h, pixels) = decode(&path);
    assert_eq!((w, h), (opts.width, opts.height));
    let bg = [BACKGROUND.0, BACKGROUND.1, BACKGROUND.2];
    let drawn = pixels.iter().filter(|&&p| p != bg).count();
    assert!(drawn > pixels.len() / 50, "{name}: only {drawn} pixels drawn");
    if let Ok(keep) = std::env::var("MOCHI_KEEP_PREVIEWS") {
        std::fs::copy(&path, Path::new(&keep).join(name)).unwrap();
    }
    pixels
}

fn count(pixels: &[[u8; 3]], c: RGBColor) -> usize {
    pixels.iter().filter(|&&p| p == [c.0, c.1, c.2]).count()
}

#[test]
fn render_obj_of_tets_has_only_surface_vertices_and_faces() {
    let mesh = split_tet();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tet.obj");
    let mut x = mesh.rest.clone();
    x[3] = 1.5; // move vertex 1
    write_obj(&path, &mesh, &x).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let v: Vec<&str> = text.lines().filter(|l| l.starts_with("v ")).collect();
    let f: Vec<&str> = text.lines().filter(|l| l.starts_with("f ")).collect();
    // The centre vertex (index 4) is interior: 4 vertices, the 4 outer faces.
    assert_eq!(v.len(), 4);
    assert_eq!(f.len(), 4);
    assert_eq!(v[1], "v 1.5 0 0");
    assert!(!text.contains("0.25"));
    let mut corners: Vec<Vec<usize>> = f
        .iter()
        .map(|l| {
            let mut c: Vec<usize> = l[2..].split(' ').map(|s| s.parse().unwrap()).collect();
            c.sort_unstable();
            c
        })
        .collect();
    corners.sort();
    assert_eq!(
        corners,
        vec![vec![1, 2, 3], vec![1, 2, 4], vec![1, 3, 4], vec![2, 3, 4]]
    );

    let cubes = two_cube_tets();
    write_obj(&path, &cubes, &cubes.rest).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 12);
    // 10 outer unit squares, 2 triangles each; the shared square is inside.
    assert_eq!(text.lines().filter(|l| l.starts_with("f ")).count(), 20);
}

#[test]
fn render_obj_of_rods_2d_and_sequences() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = rods();
    let path = dir.path().join("rods.obj");
    write_obj(&path, &mesh, &mesh.rest).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with("l ")).collect();
    assert_eq!(lines.len(), 4);
    assert_eq!(lines[1], "l 11 12 13 14 15 16 17 18 19 20");
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 40);

    let plate = plate2d();
    write_obj(&path, &plate, &plate.rest).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.lines().any(|l| l == "v 4 1 0"));
    assert_eq!(text.lines().filter(|l| l.starts_with("f ")).count(), 32);

    let frames: Vec<Vec<f64>> = (0..7).map(|_| plate.rest.clone()).collect();
    let written = write_obj_sequence(&dir.path().join("seq"), "plate", &plate, &frames, 3).unwrap();
    let names: Vec<String> = written
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["plate_00000.obj", "plate_00003.obj", "plate_00006.obj"]);
    assert!(write_obj_sequence(dir.path(), "p", &plate, &frames, 0).is_err());

    let mut bad = plate.rest.clone();
    bad[5] = f64::NAN;
    assert!(write_obj(&path, &plate, &bad).is_err());
    assert!(write_obj(&path, &plate, &bad[..4]).is_err());
}

#[test]
fn render_png_of_cloth_shows_frames_and_pins() {
    let mesh = cloth(12);
    let frames: Vec<Vec<f64>> = [0.0, 0.5, 1.0].iter().map(|&a| drape(&mesh, a)).collect();
    let refs: Vec<&[f64]> = frames.iter().map(Vec::as_slice).collect();
    let opts = RenderOptions {
        title: "cloth: frames 0, 30, 60".into(),
        highlight: (0..12).collect(),
        panel_labels: vec!["frame 0".into(), "frame 30".into(), "frame 60".into()],
        ..RenderOptions::default()
    };
    let pixels = check_render("cloth.png", &mesh, &refs, &opts);
    assert!(count(&pixels, HIGHLIGHT) > 3 * 12 * 5, "pins drawn in every panel");
}

#[test]
fn render_png_of_tets_rods_and_2d() {
    let cubes = two_cube_tets();
    let mut bent = cubes.rest.clone();
    for p in bent.chunks_exact_mut(3) {
        p[1] += 0.3 * p[0] * p[0];
    }
    let opts = RenderOptions {
        width: 640,
        height: 320,
        title: "two cubes".into(),
        ..RenderOptions::default()
    };
    check_render("tets.png", &cubes, &[&cubes.rest, &bent], &opts);
    for view in [View::Front, View::Side, View::Top] {
        let opts = RenderOptions {
            view,
            up_axis: 2,
            ..opts.clone()
        };
        check_render("tets_view.png", &cubes, &[&bent], &opts);
    }

    let strands = rods();
    let pixels = check_render(
        "rods.png",
        &strands,
        &[&strands.rest],
        &RenderOptions {
            width: 300,
            height: 300,
            title: "rods".into(),
            highlight: vec![0, 10, 20, 30],
            ..RenderOptions::default()
        },
    );
    assert!(count(&pixels, ROD) > 200);

    let plate = plate2d();
    let mut sagged = plate.rest.clone();
    for p in sagged.chunks_exact_mut(2) {
        p[1] -= 0.05 * p[0] * p[0];
    }
    let pixels = check_render(
        "plate.png",
        &plate,
        &[&plate.rest, &sagged],
        &RenderOptions {
            title: "2D plate".into(),
            ..RenderOptions::default()
        },
    );
    assert!(count(&pixels, FLAT_FILL) > 2000);
}

#[test]
fn render_camera_is_orthonormal_and_keeps_up_up() {
    for up_axis in 0..3 {
        for view in [View::ThreeQuarter, View::Front, View::Side, View::Top] {
            let c = Camera::new(view, up_axis, 3);
            for (a, b) in [(c.s, c.t), (c.t, c.w), (c.w, c.s)] {
                assert!(dot(a, b).abs() < 1e-12);
                assert!((dot(a, a) - 1.0).abs() < 1e-12);
            }
            // Right-handed: right x up = toward the viewer.
            let w = cross(c.s, c.t);
            assert!(dot(w, c.w) > 1.0 - 1e-12, "{view:?} up {up_axis}");
            let mut up = [0.0; 3];
            up[up_axis] = 1.0;
            let (_, t, _) = c.project(up);
            if view == View::Top {
                assert!(t.abs() < 1e-12);
            } else {
                assert!(t > 0.5, "{view:?} up {up_axis}: up points down");
            }
        }
    }
}

#[test]
fn render_png_draws_near_triangles_over_far_ones() {
    // A big square at z = 0 facing away (drawn orange) and a small one at z = 1 facing
    // the viewer (blue), the near one listed first: the centre must come out blue.
    let rest = vec![
        -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0, // far
        -0.3, -0.3, 1.0, 0.3, -0.3, 1.0, 0.3, 0.3, 1.0, -0.3, 0.3, 1.0, // near
    ];
    let mesh = Mesh {
        dim: 3,
        rest,
        elements: Elements::Shell(vec![[4, 5, 6], [4, 6, 7], [0, 2, 1], [0, 3, 2]]),
        attributes: None,
    };
    let opts = RenderOptions {
        width: 200,
        height: 200,
        view: View::Front,
        ..RenderOptions::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("depth.png");
    render_png(&path, &mesh, &[&mesh.rest], &opts).unwrap();
    let (w, _, pixels) = decode(&path);
    let at = |x: u32, y: u32| pixels[(y * w + x) as usize];
    let centre = at(100, 104);
    assert!(centre[2] > centre[0], "centre {centre:?} should be blue");
    let corner = at(30, 40);
    assert!(corner[0] > corner[2], "far square {corner:?} should be orange");
}

#[test]
fn render_png_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.png");
    let mesh = cloth(3);
    let opts = RenderOptions::default();
    assert!(render_png(&path, &mesh, &[], &opts).is_err());
    assert!(render_png(&path, &mesh, &[&mesh.rest[..5]], &opts).is_err());
    let mut nan = mesh.rest.clone();
    nan[0] = f64::NAN;
    assert!(render_png(&path, &mesh, &[&nan], &opts).is_err());
    let far = RenderOptions {
        highlight: vec![9],
        ..RenderOptions::default()
    };
    let e = render_png(&path, &mesh, &[&mesh.rest], &far).unwrap_err();
    assert!(format!("{e:#}").contains("bad.png"));
    let broken = Mesh {
        dim: 3,
        rest: mesh.rest.clone(),
        elements: Elements::Shell(vec![[0, 1, 99]]),
        attributes: None,
    };
    assert!(render_png(&path, &broken, &[&broken.rest], &opts).is_err());
    assert!(write_obj(&path, &broken, &broken.rest).is_err());
    let flat_cloth = Mesh {
        dim: 2,
        rest: vec![0.0; 6],
        elements: Elements::Shell(vec![[0, 1, 2]]),
        attributes: None,
    };
    assert!(render_png(&path, &flat_cloth, &[&flat_cloth.rest], &opts).is_err());
    assert!(write_obj(&path, &flat_cloth, &flat_cloth.rest).is_err());
}
