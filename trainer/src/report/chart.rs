//! Charts as PNG files: line charts of named series and labelled scatter charts.
//!
//! Text is drawn with the DejaVu Sans font built into the binary (see `trainer/assets/`),
//! so charts look the same on a bare machine without system fonts. Points that cannot be
//! drawn (non-finite values, or non-positive values on a logarithmic axis, e.g. the error
//! of a diverged rollout) are left out of the chart.

use std::path::Path;
use std::sync::OnceLock;

use crate::error::{Context, TrainerError, TrainerResult};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Size of chart images in pixels (width, height).
pub const CHART_SIZE: (u32, u32) = (960, 640);

/// A named line of (x, y) points, drawn in the given order.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Name shown in the legend.
    pub name: String,
    /// Points (x, y).
    pub points: Vec<(f64, f64)>,
}

/// One point of a scatter chart.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelledPoint {
    /// Group the point belongs to: one colour and legend entry per group (e.g. the method).
    pub group: String,
    /// Text written beside the point (e.g. the latent size); may be empty. Where labels
    /// would overlap, the later one is left out (the point is still drawn).
    pub label: String,
    /// Labelled before every point without it (e.g. the Pareto front), so that its label is
    /// the one kept where two would overlap.
    pub emphasis: bool,
    /// Horizontal coordinate.
    pub x: f64,
    /// Vertical coordinate.
    pub y: f64,
}

/// Writes a line chart of several named series, with a legend, as a PNG of [`CHART_SIZE`].
pub fn line_chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    log_y: bool,
) -> TrainerResult<()> {
    let kept: Vec<Series> = series
        .iter()
        .map(|s| Series {
            name: s.name.clone(),
            points: s
                .points
                .iter()
                .copied()
                .filter(|&(x, y)| drawable(x, false) && drawable(y, log_y))
                .collect(),
        })
        .collect();
    let all = kept.iter().flat_map(|s| s.points.iter().copied());
    let body = Body::Lines(&kept);
    let labels = Labels {
        title,
        x_label,
        y_label,
    };
    render(path, &labels, all, false, log_y, &body).with_context(|| format!("writing chart {}", path.display()))
}

/// Writes a scatter chart of labelled points, one colour and marker per group, as a PNG of
/// [`CHART_SIZE`] with a legend column of [`SCATTER_LEGEND_WIDTH`] beside it when the groups
/// are named (e.g. speed against accuracy, one group per method, labelled with the budget).
pub fn scatter_chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    points: &[LabelledPoint],
    log_x: bool,
    log_y: bool,
) -> TrainerResult<()> {
    let kept: Vec<LabelledPoint> = points
        .iter()
        .filter(|p| drawable(p.x, log_x) && drawable(p.y, log_y))
        .cloned()
        .collect();
    let all = kept.iter().map(|p| (p.x, p.y));
    let body = Body::Scatter(&kept);
    let labels = Labels {
        title,
        x_label,
        y_label,
    };
    render(path, &labels, all, log_x, log_y, &body).with_context(|| format!("writing chart {}", path.display()))
}

/// Registers the built-in font as plotters' `sans-serif` family (once per process).
pub(crate) fn register_font() -> TrainerResult<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    const DEJAVU_SANS: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font("sans-serif", FontStyle::Normal, DEJAVU_SANS).is_ok());
    if ok {
        Ok(())
    } else {
        Err(TrainerError::Drawing("the built-in font could not be loaded".into()))
    }
}

/// Colours for series and groups, in order (Tableau 10, distinguishable and print-safe).
pub(crate) const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// The `i`-th palette colour, cycling.
pub(crate) fn palette(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// Title and axis labels.
struct Labels<'a> {
    title: &'a str,
    x_label: &'a str,
    y_label: &'a str,
}

/// What is drawn inside the axes.
enum Body<'a> {
    Lines(&'a [Series]),
    Scatter(&'a [LabelledPoint]),
}

fn drawable(v: f64, log: bool) -> bool {
    v.is_finite() && (!log || v > 0.0)
}

/// Axis range covering `lo..=hi` with a margin; a single value gets a range around it.
fn padded_range(lo: f64, hi: f64, log: bool) -> (f64, f64) {
    if log {
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (1.0, 10.0) };
        let span = (hi / lo).log10().max(0.5);
        let pad = 10f64.powf(0.06 * span);
        (lo / pad, hi * pad)
    } else {
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 1.0) };
        let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
        (lo - 0.06 * span, hi + 0.06 * span)
    }
}

/// Short tick text: plain decimals for moderate magnitudes, `1e-5` style otherwise.
fn tick_text(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        s.replace(".0e", "e")
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// A scatter chart's legend: a column right of the plot, so that it hides no point and takes
/// no room from the axes (pixels: the column's width beside [`CHART_SIZE`], one row's height).
pub const SCATTER_LEGEND_WIDTH: u32 = 340;
const LEGEND_ROW_PX: i32 = 24;

/// Draws the chart with linear or logarithmic axes as asked.
fn render(
    path: &Path,
    labels: &Labels,
    points: impl Iterator<Item = (f64, f64)>,
    log_x: bool,
    log_y: bool,
    body: &Body,
) -> TrainerResult<()> {
    register_font()?;
    let (mut x_lo, mut x_hi, mut y_lo, mut y_hi) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for (x, y) in points {
        (x_lo, x_hi) = (x_lo.min(x), x_hi.max(x));
        (y_lo, y_hi) = (y_lo.min(y), y_hi.max(y));
    }
    let (x0, x1) = padded_range(x_lo, x_hi, log_x);
    let (y0, y1) = padded_range(y_lo, y_hi, log_y);
    // Scatter labels sit right of their points: leave room on the right.
    let x1 = match (body, log_x) {
        (Body::Scatter(_), true) => x1 * (x1 / x0).powf(0.06),
        (Body::Scatter(_), false) => x1 + 0.06 * (x1 - x0),
        _ => x1,
    };
    match (log_x, log_y) {
        (false, false) => draw(path, labels, x0..x1, y0..y1, body),
        (false, true) => draw(path, labels, x0..x1, (y0..y1).log_scale(), body),
        (true, false) => draw(path, labels, (x0..x1).log_scale(), y0..y1, body),
        (true, true) => draw(path, labels, (x0..x1).log_scale(), (y0..y1).log_scale(), body),
    }
}

fn draw<X, Y>(path: &Path, labels: &Labels, x: X, y: Y, body: &Body) -> TrainerResult<()>
where
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let groups = match body {
        Body::Scatter(points) => scatter_groups(points),
        Body::Lines(_) => Vec::new(),
    };
    let legend_width = if groups.iter().any(|g| !g.is_empty()) {
        SCATTER_LEGEND_WIDTH
    } else {
        0
    };
    let root = BitMapBackend::new(path, (CHART_SIZE.0 + legend_width, CHART_SIZE.1)).into_drawing_area();
    root.fill(&WHITE)?;
    // The title over the whole width, the legend column (if any) beside the plot below it.
    let titled = root.titled(labels.title, ("sans-serif", 26))?;
    let (plot, side) = titled.split_horizontally(CHART_SIZE.0);
    let mut chart = ChartBuilder::on(&plot)
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(84)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc(labels.x_label)
        .y_desc(labels.y_label)
        .x_label_formatter(&|v| tick_text(*v))
        .y_label_formatter(&|v| tick_text(*v))
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 19))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(210, 210, 210))
        .draw()?;

    match body {
        Body::Lines(series) => {
            let mut legend = false;
            for (i, s) in series.iter().enumerate() {
                let color = palette(i);
                let markers = if s.points.len() <= 40 { 3 } else { 0 };
                let line = LineSeries::new(s.points.iter().copied(), color.stroke_width(2)).point_size(markers);
                let drawn = chart.draw_series(line)?;
                if !s.name.is_empty() {
                    legend = true;
                    drawn
                        .label(s.name.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
                }
            }
            if legend {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .label_font(("sans-serif", 16))
                    .background_style(WHITE.mix(0.85))
                    .border_style(RGBColor(160, 160, 160))
                    .draw()?;
            }
        }
        Body::Scatter(points) => {
            // Each point's group (its colour and marker), found once.
            let group: Vec<usize> = points
                .iter()
                .map(|p| groups.iter().position(|g| *g == p.group).unwrap_or(0))
                .collect();
            let shaped = |shape: usize| {
                points
                    .iter()
                    .zip(group.iter().copied())
                    .filter(move |(_, i)| marker_shape(*i) == shape)
            };
            chart.draw_series(shaped(0).map(|(p, i)| Circle::new((p.x, p.y), 5, palette(i).filled())))?;
            chart.draw_series(shaped(1).map(|(p, i)| TriangleMarker::new((p.x, p.y), 7, palette(i).filled())))?;
            chart.draw_series(shaped(2).map(|(p, i)| {
                EmptyElement::at((p.x, p.y)) + Rectangle::new([(-5, -5), (5, 5)], palette(i).filled())
            }))?;
            // Labels beside their points, as many as fit without overlapping.
            let area = chart.plotting_area().get_pixel_range();
            let bounds = (area.0.start, area.1.start, area.0.end, area.1.end);
            let mut boxes = Vec::new();
            for (p, &i) in points.iter().zip(&group) {
                let (w, h) = plot.estimate_text_size(&p.label, &label_font(i))?;
                let (px, py) = chart.backend_coord(&(p.x, p.y));
                let y = py + LABEL_RISE;
                let right = (px + LABEL_GAP, y, px + LABEL_GAP + w as i32, y + h as i32);
                let left = (px - LABEL_GAP - w as i32, y, px - LABEL_GAP, y + h as i32);
                boxes.push((!p.label.is_empty()).then_some(([right, left], p.emphasis)));
            }
            let sides = place_labels(&boxes, bounds);
            let texts = points
                .iter()
                .zip(&group)
                .zip(&boxes)
                .zip(sides)
                .filter_map(|(((p, &i), candidates), side)| {
                    let (b, _) = candidates.as_ref()?;
                    let offset = (b[side?].0 - b[0].0 + LABEL_GAP, LABEL_RISE);
                    let text = Text::new(p.label.clone(), offset, label_font(i));
                    Some(EmptyElement::at((p.x, p.y)) + text)
                });
            chart.draw_series(texts)?;
            draw_scatter_legend(&side, &groups)?;
        }
    }
    root.present()?;
    Ok(())
}

/// The scatter chart's groups in order of first appearance (one colour and marker each).
fn scatter_groups(points: &[LabelledPoint]) -> Vec<&str> {
    let mut order: Vec<&str> = Vec::new();
    for p in points {
        if !order.contains(&p.group.as_str()) {
            order.push(&p.group);
        }
    }
    order
}

/// A scatter label's gap from its point and its top's rise above it, in pixels.
const LABEL_GAP: i32 = 8;
const LABEL_RISE: i32 = -16;

/// The font of the `i`-th group's labels.
fn label_font(i: usize) -> TextStyle<'static> {
    ("sans-serif", 15).into_font().color(&palette(i).mix(0.95))
}

/// A label's box in pixels: left, top, right, bottom.
type LabelBox = (i32, i32, i32, i32);

/// Where to draw each label, given its two possible boxes (right of its point, left of it)
/// and whether it is emphasised (`None`: the point has no label): emphasised labels first,
/// then in order, each on the first side where it stays inside `bounds` without overlapping a
/// label already placed, or not at all (`None`).
fn place_labels(boxes: &[Option<([LabelBox; 2], bool)>], bounds: LabelBox) -> Vec<Option<usize>> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by_key(|&i| !boxes[i].is_some_and(|(_, emphasis)| emphasis));
    let mut sides = vec![None; boxes.len()];
    let mut placed: Vec<LabelBox> = Vec::new();
    for i in order {
        let Some((candidates, _)) = &boxes[i] else { continue };
        let fits = |b: &LabelBox| {
            let inside = b.0 >= bounds.0 && b.1 >= bounds.1 && b.2 <= bounds.2 && b.3 <= bounds.3;
            inside && !placed.iter().any(|k| b.0 < k.2 && k.0 < b.2 && b.1 < k.3 && k.1 < b.3)
        };
        if let Some(side) = candidates.iter().position(fits) {
            placed.push(candidates[side]);
            sides[i] = Some(side);
        }
    }
    sides
}

/// The marker shape of the `i`-th group: a circle in each of the palette's ten colours, then a
/// triangle, then a square, so that no two groups look alike.
fn marker_shape(i: usize) -> usize {
    (i / PALETTE.len()) % 3
}

/// Draws the groups' markers and names down the legend column `side`.
fn draw_scatter_legend(side: &DrawingArea<BitMapBackend, Shift>, groups: &[&str]) -> TrainerResult<()> {
    let font = ("sans-serif", 16).into_font().color(&BLACK);
    for (i, group) in groups.iter().enumerate().filter(|(_, g)| !g.is_empty()) {
        let (x, y) = (14, 40 + LEGEND_ROW_PX * i as i32);
        let color = palette(i).filled();
        match marker_shape(i) {
            0 => side.draw(&Circle::new((x, y), 5, color))?,
            1 => side.draw(&TriangleMarker::new((x, y), 7, color))?,
            _ => side.draw(&Rectangle::new([(x - 5, y - 5), (x + 5, y + 5)], color))?,
        }
        side.draw(&Text::new(group.to_string(), (x + 16, y - 9), font.clone()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes a PNG and returns (width, height, RGB(A) bytes, channels).
    pub(crate) fn decode_png(path: &Path) -> (u32, u32, Vec<u8>, usize) {
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf, info.color_type.samples())
    }

    /// Copies a rendered chart to `$MOCHI_KEEP_PREVIEWS/` when set, for looking at it.
    fn keep(path: &Path) {
        if let Ok(dir) = std::env::var("MOCHI_KEEP_PREVIEWS") {
            std::fs::copy(path, Path::new(&dir).join(path.file_name().unwrap())).unwrap();
        }
    }

    /// Number of pixels of exactly `rgb`.
    fn count_color(path: &Path, rgb: [u8; 3]) -> usize {
        let (_, _, buf, ch) = decode_png(path);
        buf.chunks(ch).filter(|p| p[..3] == rgb).count()
    }

    #[test]
    fn chart_line_chart_draws_series_and_legend() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lines.png");
        let series = vec![
            Series {
                name: "train loss".into(),
                points: (1..200).map(|i| (i as f64, 1.0 / i as f64)).collect(),
            },
            Series {
                name: "test loss".into(),
                points: (1..200)
                    .map(|i| (i as f64, 1.5 / i as f64 + 1e-3))
                    .chain([(200.0, f64::NAN), (201.0, -1.0)])
                    .collect(),
            },
        ];
        line_chart(&path, "Loss", "epoch", "loss", &series, true).unwrap();
        keep(&path);
        let (w, h, _, _) = decode_png(&path);
        assert_eq!((w, h), CHART_SIZE);
        let [r, g, b] = [palette(0).0, palette(0).1, palette(0).2];
        assert!(count_color(&path, [r, g, b]) > 200);
        let [r, g, b] = [palette(1).0, palette(1).1, palette(1).2];
        assert!(count_color(&path, [r, g, b]) > 200);
    }

    #[test]
    fn chart_scatter_chart_colours_groups() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scatter.png");
        let mut points = Vec::new();
        for (g, method) in ["ours", "vanilla subspace", "full space"].iter().enumerate() {
            for (k, latent) in [8, 16, 32].iter().enumerate() {
                points.push(LabelledPoint {
                    group: method.to_string(),
                    label: format!("r={latent}"),
                    emphasis: k == 0,
                    x: 10f64.powi(g as i32 - 1) * (k + 1) as f64,
                    y: 0.05 / (k + 1) as f64 / (g + 1) as f64,
                });
            }
        }
        scatter_chart(&path, "Speed vs accuracy", "ms / frame", "error", &points, true, true).unwrap();
        keep(&path);
        for g in 0..3 {
            let c = palette(g);
            assert!(count_color(&path, [c.0, c.1, c.2]) > 60, "group {g}");
        }
        // The legend is a column beside the plot.
        assert_eq!(decode_png(&path).0, CHART_SIZE.0 + SCATTER_LEGEND_WIDTH);
        // A single point and linear axes still give a valid chart.
        scatter_chart(&path, "one", "x", "y", &points[..1], false, false).unwrap();
        assert_eq!(decode_png(&path).1, CHART_SIZE.1);
    }

    #[test]
    fn chart_groups_past_the_palette_get_other_markers() {
        assert_eq!((marker_shape(0), marker_shape(9)), (0, 0));
        assert_eq!((marker_shape(10), marker_shape(19), marker_shape(20)), (1, 1, 2));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("many.png");
        let points: Vec<LabelledPoint> = (0..13)
            .map(|g| LabelledPoint {
                group: format!("method {g}"),
                label: String::new(),
                emphasis: false,
                x: 1.0 + g as f64,
                y: 1.0,
            })
            .collect();
        scatter_chart(&path, "thirteen", "x", "y", &points, true, true).unwrap();
        keep(&path);
        // Group 10 shares group 0's colour: its triangle and legend entry add to the circles'.
        let c = palette(0);
        let alone = {
            scatter_chart(&path, "ten", "x", "y", &points[..10], true, true).unwrap();
            count_color(&path, [c.0, c.1, c.2])
        };
        scatter_chart(&path, "thirteen", "x", "y", &points, true, true).unwrap();
        assert!(count_color(&path, [c.0, c.1, c.2]) > alone + 40);
    }

    #[test]
    fn chart_labels_that_would_overlap_are_left_out_emphasised_first() {
        let bounds = (0, 0, 100, 100);
        let off = (-50, 0, -40, 0); // a left box that never fits
        let boxes = [
            Some(([(10, 10, 40, 20), off], false)),
            Some(([(30, 15, 60, 25), off], true)), // overlaps the first: emphasised, so it is kept
            Some(([(70, 10, 99, 20), off], false)), // clear of both
            Some(([(10, 50, 40, 60), off], false)),
            Some(([(20, 55, 50, 65), off], false)), // overlaps the one before it: the first stays
            Some(([(80, 90, 120, 99), (40, 90, 72, 99)], false)), // past the right edge: drawn left
            None,                                   // no label: blocks nothing
            Some(([(5, 30, 95, 40), off], false)),
        ];
        let sides = place_labels(&boxes, bounds);
        assert_eq!(sides, [None, Some(0), Some(0), Some(0), None, Some(1), None, Some(0)]);
    }

    #[test]
    fn chart_empty_and_unwritable() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.png");
        line_chart(&path, "nothing", "x", "y", &[], false).unwrap();
        assert_eq!(decode_png(&path).1, CHART_SIZE.1);
        let bad = dir.path().join("no-such-dir").join("x.png");
        let e = line_chart(&bad, "t", "x", "y", &[], false).unwrap_err();
        assert!(format!("{e:#}").contains("x.png"));
    }

    #[test]
    fn chart_tick_text_is_short() {
        assert_eq!(tick_text(0.0), "0");
        assert_eq!(tick_text(0.25), "0.25");
        assert_eq!(tick_text(100.0), "100");
        assert_eq!(tick_text(1e-5), "1e-5");
        assert_eq!(tick_text(2.5e6), "2.5e6");
    }
}
