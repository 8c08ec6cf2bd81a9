//! Frames for people to look at: Wavefront OBJ files ([`obj`]) and PNG previews.
//!
//! PNG previews show one or more frames side by side in panels that share one framing, so
//! motion between panels is visible; triangles are filled with two-sided Lambert shading
//! (front faces blue, back faces orange) and drawn far to near.

mod obj;
#[cfg(test)]
mod tests;

use std::path::Path;

use crate::error::{bail, Context, TrainerResult};
use plotters::prelude::*;

use crate::report::chart::register_font;
use mochi_sim::mesh::{Elements, Mesh};

use obj::{check_frame, check_mesh};
pub use obj::{write_obj, write_obj_sequence};

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
