//! Frames for people to look at: Wavefront OBJ files and PNG previews.
//!
//! OBJ files hold what is drawn: the surface of a tet mesh (only its surface vertices,
//! renumbered), all triangles of cloth and 2D meshes (2D padded with z = 0), and rods as
//! `l` polylines. PNG previews show one or more frames side by side in panels that share
//! one framing, so motion between panels is visible; triangles are filled with two-sided
//! Lambert shading (front faces blue, back faces orange) and drawn far to near.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::{bail, Context, TrainerError, TrainerResult};
use plotters::prelude::*;

use crate::report::chart::register_font;
use mochi_sim::mesh::{Elements, Mesh};

// ---------------------------------------------------------------------------------------
// OBJ

/// What an OBJ file of a mesh holds, with vertex indices renumbered to the written subset.
struct ObjTopology {
    /// Original indices of the vertices written, in order.
    vertices: Vec<usize>,
    /// Triangles in written (0-based) indices.
    faces: Vec<[usize; 3]>,
    /// Polylines in written (0-based) indices.
    lines: Vec<Vec<usize>>,
}

impl ObjTopology {
    fn new(mesh: &Mesh) -> TrainerResult<Self> {
        check_mesh(mesh)?;
        if let Elements::Rods(rods) = &mesh.elements {
            return Ok(ObjTopology {
                vertices: (0..mesh.num_vertices()).collect(),
                faces: Vec::new(),
                lines: rods.iter().filter(|r| r.len() >= 2).cloned().collect(),
            });
        }
        let vertices = mesh.surface_vertices();
        let mut new_index = vec![usize::MAX; mesh.num_vertices()];
        for (i, &v) in vertices.iter().enumerate() {
            new_index[v] = i;
        }
        let faces = mesh
            .surface_triangles()
            .iter()
            .map(|t| t.map(|v| new_index[v]))
            .collect();
        Ok(ObjTopology {
            vertices,
            faces,
            lines: Vec::new(),
        })
    }

    fn write(&self, path: &Path, dim: usize, x: &[f64]) -> TrainerResult<()> {
        let mut text = String::with_capacity(40 * (self.vertices.len() + self.faces.len()));
        text.push_str("# mochi frame\n");
        for &v in &self.vertices {
            let p = &x[v * dim..(v + 1) * dim];
            let z = if dim == 3 { p[2] } else { 0.0 };
            // `{}` prints the shortest text that reads back as the same f64.
            writeln!(text, "v {} {} {}", p[0], p[1], z)?;
        }
        for f in &self.faces {
            writeln!(text, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
        }
        for line in &self.lines {
            text.push('l');
            for v in line {
                write!(text, " {}", v + 1)?;
            }
            text.push('\n');
        }
        let write = || -> std::io::Result<()> {
            let mut file = BufWriter::new(File::create(path)?);
            file.write_all(text.as_bytes())?;
            file.flush()
        };
        write().map_err(|e| TrainerError::io(path, e))
    }
}

/// Writes positions `x` (flat, `mesh.dim` per vertex) of `mesh` as a Wavefront OBJ file.
pub fn write_obj(path: &Path, mesh: &Mesh, x: &[f64]) -> TrainerResult<()> {
    let topology = ObjTopology::new(mesh)?;
    check_frame(mesh, x).with_context(|| format!("writing {}", path.display()))?;
    topology
        .write(path, mesh.dim, x)
        .with_context(|| format!("writing {}", path.display()))
}

/// Writes every `every`-th frame (0, every, 2 every, ...) as `dir/{stem}_{frame:05}.obj`,
/// creating `dir` if needed; returns the paths written.
pub fn write_obj_sequence(
    dir: &Path,
    stem: &str,
    mesh: &Mesh,
    frames: &[Vec<f64>],
    every: usize,
) -> TrainerResult<Vec<PathBuf>> {
    if every == 0 {
        bail!("write_obj_sequence: `every` must be at least 1");
    }
    let topology = ObjTopology::new(mesh)?;
    crate::error::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for (f, x) in frames.iter().enumerate().step_by(every) {
        let path = dir.join(format!("{stem}_{f:05}.obj"));
        check_frame(mesh, x).with_context(|| format!("frame {f}"))?;
        topology
            .write(&path, mesh.dim, x)
            .with_context(|| format!("writing {}", path.display()))?;
        written.push(path);
    }
    Ok(written)
}

/// Checks the mesh's dimension against its kind and that every element index refers to a
/// vertex of the mesh.
fn check_mesh(mesh: &Mesh) -> TrainerResult<()> {
    let dim = match mesh.elements {
        Elements::Triangles(_) => 2,
        _ => 3,
    };
    if mesh.dim != dim || !mesh.rest.len().is_multiple_of(dim) {
        bail!(
            "mesh of dimension {} with {} rest coordinates; its elements need {dim}D",
            mesh.dim,
            mesh.rest.len()
        );
    }
    let n = mesh.num_vertices();
    let bad = |e: usize| TrainerError::Invalid(format!("element {e} refers to a vertex beyond the {n} of the mesh"));
    match &mesh.elements {
        Elements::Tets(t) => t.iter().position(|e| e.iter().any(|&v| v >= n)),
        Elements::Triangles(t) | Elements::Shell(t) => t.iter().position(|e| e.iter().any(|&v| v >= n)),
        Elements::Rods(r) => r.iter().position(|e| e.iter().any(|&v| v >= n)),
    }
    .map_or(Ok(()), |e| Err(bad(e)))
}

/// Checks that `x` has one finite point per vertex of a mesh that passed [`check_mesh`].
fn check_frame(mesh: &Mesh, x: &[f64]) -> TrainerResult<()> {
    if x.len() != mesh.rest.len() {
        bail!(
            "{} coordinates for a mesh of {} vertices in {}D",
            x.len(),
            mesh.num_vertices(),
            mesh.dim
        );
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        bail!("vertex {} has a non-finite coordinate {}", i / mesh.dim, x[i]);
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// PNG previews

/// Where a 3D preview is seen from (2D meshes are always drawn in their plane).
///
/// The screen's right is +x and "front" (toward the viewer) is +z when y is up, -y when
/// z is up; with x up, right is +z and front +y.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// From the front, above and to the right.
    ThreeQuarter,
    /// From the front.
    Front,
    /// From the right.
    Side,
    /// From above, front at the bottom of the image.
    Top,
}

/// How [`render_png`] draws.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels (all panels together).
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Title drawn at the top; none if empty.
    pub title: String,
    /// Viewpoint for 3D meshes.
    pub view: View,
    /// Axis that points up on screen: 0 = x, 1 = y, 2 = z.
    pub up_axis: usize,
    /// Vertices drawn as red dots on top (e.g. pinned vertices).
    pub highlight: Vec<usize>,
    /// Per panel, vertices drawn as green dots (e.g. the adaptive solver's enriched ones);
    /// none by default.
    pub marked: Vec<Vec<usize>>,
    /// Caption of each panel (e.g. `frame 30`); missing ones are left blank.
    pub panel_labels: Vec<String>,
    /// The first this many vertices are what the view is framed on (e.g. the body, with
    /// obstacle meshes after it drawn but cropped); default all.
    pub framed_vertices: Option<usize>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 960,
            height: 400,
            title: String::new(),
            view: View::ThreeQuarter,
            up_axis: 1,
            highlight: Vec::new(),
            marked: Vec::new(),
            panel_labels: Vec::new(),
            framed_vertices: None,
        }
    }
}

const BACKGROUND: RGBColor = RGBColor(250, 250, 248);
const FRONT: [f64; 3] = [105.0, 155.0, 225.0];
const BACK: [f64; 3] = [230.0, 150.0, 80.0];
const FLAT_FILL: RGBColor = RGBColor(160, 190, 232);
const EDGE: RGBColor = RGBColor(40, 60, 100);
const ROD: RGBColor = RGBColor(30, 70, 140);
const HIGHLIGHT: RGBColor = RGBColor(220, 30, 30);
/// Colour of marked vertices (the adaptive solver's enriched ones).
const MARKED: RGBColor = RGBColor(20, 170, 60);
const PANEL_BORDER: RGBColor = RGBColor(205, 205, 205);
/// Above this many triangles, edges are not outlined (they would only darken the image).
const MAX_OUTLINED_TRIANGLES: usize = 3000;

/// Orthographic camera: screen right `s`, screen up `t`, toward the viewer `w`.
struct Camera {
    s: [f64; 3],
    t: [f64; 3],
    w: [f64; 3],
}

impl Camera {
    fn new(view: View, up_axis: usize, dim: usize) -> Self {
        let axis = |i: usize| {
            let mut e = [0.0; 3];
            e[i % 3] = 1.0;
            e
        };
        if dim == 2 {
            return Camera {
                s: axis(0),
                t: axis(1),
                w: axis(2),
            };
        }
        // Right-handed (right, up, toward the viewer): x right where it is not up.
        let (right, front) = match up_axis {
            0 => (axis(2), axis(1)),
            1 => (axis(0), axis(2)),
            _ => (axis(0), scale3(axis(1), -1.0)),
        };
        let up = axis(up_axis);
        let (eye, screen_up) = match view {
            View::ThreeQuarter => (normalize(add3(add3(scale3(right, 0.75), scale3(up, 0.6)), front)), up),
            View::Front => (front, up),
            View::Side => (right, up),
            View::Top => (up, scale3(front, -1.0)),
        };
        let s = normalize(cross(screen_up, eye));
        let t = cross(eye, s);
        Camera { s, t, w: eye }
    }

    /// Screen coordinates (right, up) and depth (larger is nearer) of a point.
    fn project(&self, p: [f64; 3]) -> (f64, f64, f64) {
        (dot(p, self.s), dot(p, self.t), dot(p, self.w))
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale3(a: [f64; 3], k: f64) -> [f64; 3] {
    [a[0] * k, a[1] * k, a[2] * k]
}
fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        scale3(a, 1.0 / n)
    } else {
        a
    }
}

/// Vertex `v` of flat positions `x` with `dim` coordinates, padded to 3D.
fn point(x: &[f64], dim: usize, v: usize) -> [f64; 3] {
    let p = &x[v * dim..(v + 1) * dim];
    [p[0], p[1], if dim == 3 { p[2] } else { 0.0 }]
}

/// Maps projected coordinates to pixels of a panel; the same for every panel.
struct Framing {
    scale: f64,
    center: (f64, f64),
    panel: (f64, f64),
    /// Pixels at the top of a panel kept for its caption.
    top: f64,
}

impl Framing {
    fn to_pixel(&self, s: f64, t: f64) -> (i32, i32) {
        let x = self.panel.0 / 2.0 + (s - self.center.0) * self.scale;
        let y = self.top + (self.panel.1 - self.top) / 2.0 - (t - self.center.1) * self.scale;
        (x.round() as i32, y.round() as i32)
    }
}

/// Writes a PNG preview of one or more frames (flat positions, `mesh.dim` per vertex) side
/// by side, one panel each, framed alike so that motion shows.
pub fn render_png(path: &Path, mesh: &Mesh, frames: &[&[f64]], opts: &RenderOptions) -> TrainerResult<()> {
    draw_preview(path, mesh, frames, opts).with_context(|| format!("rendering {}", path.display()))
}

fn draw_preview(path: &Path, mesh: &Mesh, frames: &[&[f64]], opts: &RenderOptions) -> TrainerResult<()> {
    if frames.is_empty() {
        bail!("no frames to draw");
    }
    if opts.width < 16 || opts.height < 16 {
        bail!("image size {}x{} is too small", opts.width, opts.height);
    }
    if opts.up_axis > 2 {
        bail!("up_axis {} is not 0, 1 or 2", opts.up_axis);
    }
    check_mesh(mesh)?;
    for (f, x) in frames.iter().enumerate() {
        check_frame(mesh, x).with_context(|| format!("frame {f}"))?;
    }
    let n = mesh.num_vertices();
    if let Some(&v) = opts
        .highlight
        .iter()
        .chain(opts.marked.iter().flatten())
        .find(|&&v| v >= n)
    {
        bail!("highlighted vertex {v} is beyond the {n} of the mesh");
    }
    register_font()?;

    let camera = Camera::new(opts.view, opts.up_axis, mesh.dim);
    let triangles = mesh.surface_triangles();
    let mut shown = mesh.surface_vertices();
    shown.extend_from_slice(&opts.highlight);

    let root = BitMapBackend::new(path, (opts.width, opts.height)).into_drawing_area();
    root.fill(&BACKGROUND)?;
    let body = if opts.title.is_empty() {
        root.clone()
    } else {
        root.titled(&opts.title, ("sans-serif", 22).into_font().color(&BLACK))?
    };
    let panels = body.split_evenly((1, frames.len()));
    let (pw, ph) = panels[0].dim_in_pixel();
    let top = if opts.panel_labels.is_empty() { 8.0 } else { 26.0 };
    let framed: Vec<usize> = match opts.framed_vertices {
        Some(n) => shown.iter().copied().filter(|&v| v < n).collect(),
        None => shown.clone(),
    };
    let framing = frame_all(&camera, mesh.dim, frames, &framed, (pw as f64, ph as f64), top);

    for (i, (panel, x)) in panels.iter().zip(frames).enumerate() {
        let (pw, ph) = panel.dim_in_pixel();
        if frames.len() > 1 {
            let (w, h) = (pw as i32 - 1, ph as i32 - 1);
            panel.draw(&PathElement::new(
                vec![(0, 0), (w, 0), (w, h), (0, h), (0, 0)],
                PANEL_BORDER,
            ))?;
        }
        match &mesh.elements {
            Elements::Rods(rods) => draw_rods(panel, &camera, &framing, mesh.dim, x, rods)?,
            Elements::Triangles(_) => draw_flat(panel, &camera, &framing, x, &triangles)?,
            Elements::Tets(_) | Elements::Shell(_) => draw_shaded(panel, &camera, &framing, x, &triangles)?,
        }
        for &v in opts.marked.get(i).into_iter().flatten() {
            let (s, t, _) = camera.project(point(x, mesh.dim, v));
            panel.draw(&Circle::new(framing.to_pixel(s, t), 2, MARKED.filled()))?;
        }
        for &v in &opts.highlight {
            let (s, t, _) = camera.project(point(x, mesh.dim, v));
            panel.draw(&Circle::new(framing.to_pixel(s, t), 3, HIGHLIGHT.filled()))?;
        }
        if let Some(label) = opts.panel_labels.get(i) {
            panel.draw(&Text::new(
                label.as_str(),
                (8, 5),
                ("sans-serif", 16).into_font().color(&BLACK),
            ))?;
        }
    }
    root.present()?;
    Ok(())
}

/// One framing for all panels: the projected bounding box of the drawn vertices of every
/// frame, fitted into a panel with a margin.
fn frame_all(camera: &Camera, dim: usize, frames: &[&[f64]], shown: &[usize], panel: (f64, f64), top: f64) -> Framing {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for x in frames {
        for &v in shown {
            let (s, t, _) = camera.project(point(x, dim, v));
            lo = [lo[0].min(s), lo[1].min(t)];
            hi = [hi[0].max(s), hi[1].max(t)];
        }
    }
    if lo[0] > hi[0] {
        (lo, hi) = ([-1.0; 2], [1.0; 2]);
    }
    let margin = 12.0;
    let usable = (
        (panel.0 - 2.0 * margin).max(1.0),
        (panel.1 - top - 2.0 * margin).max(1.0),
    );
    let span = (hi[0] - lo[0], hi[1] - lo[1]);
    let scale = (usable.0 / span.0.max(1e-12)).min(usable.1 / span.1.max(1e-12));
    let scale = if span.0.max(span.1) < 1e-12 { 1.0 } else { scale };
    Framing {
        scale,
        center: ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0),
        panel,
        top: top + margin / 2.0,
    }
}

type Panel<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// Triangles in 3D: two-sided Lambert shading, painter's algorithm.
fn draw_shaded(
    panel: &Panel,
    camera: &Camera,
    framing: &Framing,
    x: &[f64],
    triangles: &[[usize; 3]],
) -> TrainerResult<()> {
    // Key light from the upper left, in front: not from the eye, so that slopes facing the
    // viewer still differ in shade; a box shows three distinct shades.
    let light = normalize(add3(
        add3(scale3(camera.s, -0.5), scale3(camera.t, 0.7)),
        scale3(camera.w, 0.5),
    ));
    let mut order: Vec<(f64, usize)> = triangles
        .iter()
        .enumerate()
        .map(|(i, tri)| {
            let depth: f64 = tri.iter().map(|&v| dot(point(x, 3, v), camera.w)).sum();
            (depth, i)
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let outline = triangles.len() <= MAX_OUTLINED_TRIANGLES;
    for (_, i) in order {
        let p = triangles[i].map(|v| point(x, 3, v));
        let normal = normalize(cross(sub3(p[1], p[0]), sub3(p[2], p[0])));
        let facing = dot(normal, camera.w);
        let base = if facing >= 0.0 { FRONT } else { BACK };
        let lit = 0.4 + 0.6 * dot(normal, light).abs();
        let shade = |k: f64| {
            RGBColor(
                (base[0] * lit * k).min(255.0) as u8,
                (base[1] * lit * k).min(255.0) as u8,
                (base[2] * lit * k).min(255.0) as u8,
            )
        };
        let pixels: Vec<(i32, i32)> = p
            .iter()
            .map(|&q| {
                let (s, t, _) = camera.project(q);
                framing.to_pixel(s, t)
            })
            .collect();
        panel.draw(&Polygon::new(pixels.clone(), shade(1.0).filled()))?;
        if outline {
            let mut closed = pixels;
            closed.push(closed[0]);
            panel.draw(&PathElement::new(closed, shade(0.8)))?;
        }
    }
    Ok(())
}

/// Triangles in 2D: flat fill with edges.
fn draw_flat(
    panel: &Panel,
    camera: &Camera,
    framing: &Framing,
    x: &[f64],
    triangles: &[[usize; 3]],
) -> TrainerResult<()> {
    let pixel = |v: usize| {
        let (s, t, _) = camera.project(point(x, 2, v));
        framing.to_pixel(s, t)
    };
    for tri in triangles {
        panel.draw(&Polygon::new(tri.map(pixel).to_vec(), FLAT_FILL.filled()))?;
    }
    let edge_style = EDGE.mix(0.7);
    for tri in triangles {
        let p = tri.map(pixel);
        panel.draw(&PathElement::new(vec![p[0], p[1], p[2], p[0]], edge_style))?;
    }
    Ok(())
}

/// Rods: polylines, far ones first.
fn draw_rods(
    panel: &Panel,
    camera: &Camera,
    framing: &Framing,
    dim: usize,
    x: &[f64],
    rods: &[Vec<usize>],
) -> TrainerResult<()> {
    let mut order: Vec<(f64, usize)> = rods
        .iter()
        .enumerate()
        .map(|(i, rod)| {
            let depth = rod.iter().map(|&v| camera.project(point(x, dim, v)).2).sum::<f64>() / rod.len().max(1) as f64;
            (depth, i)
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (_, i) in order {
        let pixels: Vec<(i32, i32)> = rods[i]
            .iter()
            .map(|&v| {
                let (s, t, _) = camera.project(point(x, dim, v));
                framing.to_pixel(s, t)
            })
            .collect();
        panel.draw(&PathElement::new(pixels.clone(), ROD.stroke_width(2)))?;
        for &p in &pixels {
            panel.draw(&Circle::new(p, 2, ROD.filled()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
