//! Charts as PNG files: line charts of named series and labelled scatter charts.
//!
//! Text is drawn with the DejaVu Sans font built into the binary (see `trainer/assets/`),
//! so charts look the same on a bare machine without system fonts. Points that cannot be
//! drawn (non-finite values, or non-positive values on a logarithmic axis, e.g. the error
//! of a diverged rollout) are left out of the chart.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::OnceLock;

use crate::error::{Context, TrainerError, TrainerResult};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
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
    /// Text written beside the point (e.g. the latent size); may be empty.
    pub label: String,
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

/// Writes a scatter chart of labelled points, coloured by group, as a PNG of [`CHART_SIZE`]
/// (e.g. speed against accuracy, one group per method, labelled with the latent size).
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

/// Height of one legend row, the legend's padding and the plotting area's height, in pixels
/// (for the headroom a scatter chart leaves its legend).
const LEGEND_ROW_PX: f64 = 24.0;
const LEGEND_PAD_PX: f64 = 24.0;
const PLOT_HEIGHT_PX: f64 = 500.0;

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
    // The legend sits in the upper right: above the points, so it hides none of them.
    let y1 = match body {
        Body::Scatter(points) => {
            let groups: std::collections::BTreeSet<&str> = points
                .iter()
                .map(|p| p.group.as_str())
                .filter(|g| !g.is_empty())
                .collect();
            let share = (LEGEND_ROW_PX * groups.len() as f64 + LEGEND_PAD_PX) / PLOT_HEIGHT_PX;
            let grow = share.min(0.7) / (1.0 - share.min(0.7));
            match (groups.is_empty(), log_y) {
                (true, _) => y1,
                (false, true) => y1 * (y1 / y0).powf(grow),
                (false, false) => y1 + grow * (y1 - y0),
            }
        }
        _ => y1,
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
    let root = BitMapBackend::new(path, CHART_SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(labels.title, ("sans-serif", 26))
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

    let mut legend = false;
    match body {
        Body::Lines(series) => {
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
        }
        Body::Scatter(points) => {
            let mut groups: BTreeMap<&str, Vec<&LabelledPoint>> = BTreeMap::new();
            let mut order: Vec<&str> = Vec::new();
            for p in points.iter() {
                if !groups.contains_key(p.group.as_str()) {
                    order.push(&p.group);
                }
                groups.entry(&p.group).or_default().push(p);
            }
            for (i, group) in order.iter().enumerate() {
                let color = palette(i);
                let font = ("sans-serif", 15).into_font().color(&color.mix(0.95));
                let drawn = chart.draw_series(groups[group].iter().map(|p| {
                    EmptyElement::at((p.x, p.y))
                        + Circle::new((0, 0), 5, color.filled())
                        + Text::new(p.label.clone(), (8, -16), font.clone())
                }))?;
                if !group.is_empty() {
                    legend = true;
                    drawn
                        .label(*group)
                        .legend(move |(x, y)| Circle::new((x + 12, y), 5, color.filled()));
                }
            }
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
    root.present()?;
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
        // A single point and linear axes still give a valid chart.
        scatter_chart(&path, "one", "x", "y", &points[..1], false, false).unwrap();
        assert_eq!(decode_png(&path).0, CHART_SIZE.0);
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
