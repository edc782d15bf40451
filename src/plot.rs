//! Small PNG figure renderer: vertically stacked line-plot panels.
//!
//! Uses plotters' bitmap backend with an embedded DejaVu Sans font (ab_glyph),
//! and encodes the RGB buffer with the `png` crate. Output is deterministic.

use std::sync::Once;

use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::register_font;

static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static FONT_INIT: Once = Once::new();

fn ensure_font() {
    FONT_INIT.call_once(|| {
        // The embedded font is known-good; a failure here would surface as
        // text rendering errors later, so ignoring the result is safe.
        let _ = register_font("sans-serif", FontStyle::Normal, FONT_BYTES);
    });
}

/// One line series. `x` and `y` must have equal length. Non-finite values
/// (NaN, ±inf) break the line.
pub struct Series<'a> {
    pub label: String,
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub look: Look,
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Look {
    /// A line in the panel's next palette colour.
    Line,
    /// What was measured: near-black, drawn after (over) every other series of its panel.
    Observed,
    /// A prediction to compare with what was measured: its palette colour, lighter and thinner.
    Model,
    /// Points without a line (one per run, say), in the palette colour.
    Points,
}

impl<'a> Series<'a> {
    pub fn new(label: impl Into<String>, x: &'a [f64], y: &'a [f64]) -> Self {
        Series { label: label.into(), x, y, look: Look::Line }
    }

    pub fn observed(self) -> Self {
        Series { look: Look::Observed, ..self }
    }

    pub fn model(self) -> Self {
        Series { look: Look::Model, ..self }
    }

    pub fn points(self) -> Self {
        Series { look: Look::Points, ..self }
    }
}

/// A vertical dashed line at `x` with a text label.
pub struct Marker {
    pub x: f64,
    pub label: String,
}

/// One plot panel (one set of axes).
#[derive(Default)]
pub struct Panel<'a> {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series<'a>>,
    pub markers: Vec<Marker>,
    /// Logarithmic y axis; non-positive y values are skipped (break the line).
    pub log_y: bool,
    /// x intervals shaded behind the data (e.g. a located time window).
    pub spans: Vec<(f64, f64)>,
}

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),  // blue
    RGBColor(214, 39, 40),   // red
    RGBColor(44, 160, 44),   // green
    RGBColor(255, 127, 14),  // orange
    RGBColor(148, 103, 189), // purple
    RGBColor(140, 86, 75),   // brown
    RGBColor(227, 119, 194), // pink
    RGBColor(23, 190, 207),  // cyan
];
const MARKER_COLOR: RGBColor = RGBColor(90, 90, 90);
const OBSERVED_COLOR: RGBColor = RGBColor(20, 20, 20);
const SPAN_COLOR: RGBColor = RGBColor(255, 236, 204);

/// Why a figure could not be drawn.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlotError {
    #[error("figure size {width}x{height} is too small")]
    TooSmall { width: u32, height: u32 },
    #[error("figure size {width}x{height} with a {side_width} px side panel is too small")]
    SideTooWide { width: u32, height: u32, side_width: u32 },
    #[error("panel {panel} series '{label}': x has {x} points but y has {y}")]
    Lengths { panel: usize, label: String, x: usize, y: usize },
    /// The drawing library's error, as its `Debug` names it.
    #[error("plot error: {0}")]
    Drawing(String),
}

/// Render `panels` stacked vertically under an overall `title` into a PNG
/// (RGB, 8 bit) of `width` x `height` pixels.
pub fn render_png(title: &str, panels: &[Panel<'_>], width: u32, height: u32) -> Result<Vec<u8>, PlotError> {
    if width < 16 || height < 16 {
        return Err(PlotError::TooSmall { width, height });
    }
    render_canvas(title, panels.iter(), width, height, |root, body| {
        if !panels.is_empty() {
            for (panel, area) in panels.iter().zip(body.split_evenly((panels.len(), 1)).iter()) {
                draw_panel(root, area, panel)?;
            }
        }
        Ok(())
    })
}

/// Like [`render_png`], with one more panel to the right of the stack, drawn with equal scales
/// on both axes (an x–y trajectory, say) and filling the figure's height. `side_width` is its
/// share of the width in pixels. Markers of the side panel are ignored (they are vertical lines).
pub fn render_png_with_side(
    title: &str,
    panels: &[Panel<'_>],
    side: &Panel<'_>,
    side_width: u32,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, PlotError> {
    if width < 16 || height < 16 || side_width + 16 > width {
        return Err(PlotError::SideTooWide { width, height, side_width });
    }
    render_canvas(title, panels.iter().chain(std::iter::once(side)), width, height, |root, body| {
        let (stack, right) = body.split_horizontally(width - side_width);
        if !panels.is_empty() {
            for (panel, area) in panels.iter().zip(stack.split_evenly((panels.len(), 1)).iter()) {
                draw_panel(root, area, panel)?;
            }
        }
        let (xr, yr) = equal_aspect_ranges(side, right.dim_in_pixel());
        let side = Panel { markers: Vec::new(), log_y: false, ..clone_panel(side) };
        draw_panel_with(root, &right, &side, xr.0..xr.1, yr.0..yr.1)
    })
}

/// Checks every series of `panels`, lets `draw` fill a white canvas (the whole figure, and its
/// body under the title when there is one) and encodes it.
fn render_canvas<'p, 'd: 'p>(
    title: &str,
    panels: impl Iterator<Item = &'p Panel<'d>>,
    width: u32,
    height: u32,
    draw: impl for<'b> FnOnce(&Root<'b>, &Root<'b>) -> Result<(), PlotError>,
) -> Result<Vec<u8>, PlotError> {
    for (panel, p) in panels.enumerate() {
        for s in &p.series {
            if s.x.len() != s.y.len() {
                return Err(PlotError::Lengths { panel, label: s.label.clone(), x: s.x.len(), y: s.y.len() });
            }
        }
    }
    ensure_font();
    let mut buf = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let body = if title.is_empty() {
            root.clone()
        } else {
            root.titled(title, ("sans-serif", 24).into_font().color(&BLACK)).map_err(err)?
        };
        draw(&root, &body)?;
        root.present().map_err(err)?;
    }
    let (level, filter) = FIGURE_COMPRESSION;
    Ok(encode_rgb_png(&buf, width, height, level, filter))
}

fn clone_panel<'a>(p: &Panel<'a>) -> Panel<'a> {
    Panel {
        title: p.title.clone(),
        x_label: p.x_label.clone(),
        y_label: p.y_label.clone(),
        series: p.series.iter().map(|s| Series { label: s.label.clone(), ..*s }).collect(),
        markers: Vec::new(),
        log_y: false,
        spans: Vec::new(),
    }
}

/// Data ranges widened so one unit spans as many pixels on x as on y, given the panel's size
/// (less the axis label areas of [`draw_panel_with`]).
fn equal_aspect_ranges(p: &Panel<'_>, (w, h): (u32, u32)) -> ((f64, f64), (f64, f64)) {
    let ((x0, x1), (y0, y1)) = panel_ranges(&Panel { log_y: false, ..clone_panel(p) });
    let plot_w = (f64::from(w) - 70.0 - 28.0).max(1.0);
    let plot_h = (f64::from(h) - 40.0 - 50.0).max(1.0);
    let scale = ((x1 - x0) / plot_w).max((y1 - y0) / plot_h);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (hx, hy) = (0.5 * scale * plot_w, 0.5 * scale * plot_h);
    ((cx - hx, cx + hx), (cy - hy, cy + hy))
}

fn err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Drawing(format!("{e:?}"))
}

/// The PNG row filter (one for every row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowFilter {
    None,
    /// Each byte minus the byte one pixel to its left.
    Sub,
    /// Each byte minus the byte above it.
    Up,
}

/// How figures are compressed: zlib level 1 on unfiltered rows. Measured on a 1100×900 stage
/// figure (`examples/png_encoding.rs`, docs/benchmarks.md "Figures"): level 6 (the former
/// setting) 60 KB in 31–51 ms; level 1 about 1.6× the bytes in a tenth of the time, so a
/// figure no longer costs more than the simulation it shows; the png crate's fast mode is 4–25×
/// the bytes.
pub const FIGURE_COMPRESSION: (u32, RowFilter) = (1, RowFilter::None);

/// An 8-bit RGB PNG of `rgb` (rows top to bottom), its pixels deflated by zlib at `level`
/// (0–9) after `filter`: the three chunks written here, so the level is the caller's choice.
pub fn encode_rgb_png(rgb: &[u8], width: u32, height: u32, level: u32, filter: RowFilter) -> Vec<u8> {
    use std::io::Write as _;
    let row = 3 * width as usize;
    assert_eq!(rgb.len(), row * height as usize, "RGB pixels of a {width}x{height} image");
    let mut rows = Vec::with_capacity((row + 1) * height as usize);
    for (y, line) in rgb.chunks_exact(row).enumerate() {
        match filter {
            RowFilter::None => {
                rows.push(0);
                rows.extend_from_slice(line);
            }
            RowFilter::Sub => {
                rows.push(1);
                rows.extend_from_slice(&line[..3]);
                rows.extend(line[3..].iter().zip(line).map(|(a, b)| a.wrapping_sub(*b)));
            }
            RowFilter::Up => {
                rows.push(2);
                match y {
                    0 => rows.extend_from_slice(line),
                    _ => rows.extend(line.iter().zip(&rgb[(y - 1) * row..y * row]).map(|(a, b)| a.wrapping_sub(*b))),
                }
            }
        }
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(level));
    z.write_all(&rows).expect("writing to memory");
    let idat = z.finish().expect("writing to memory");
    let mut out = Vec::with_capacity(idat.len() + 64);
    out.extend_from_slice(b"\x89PNG\r\n\x1a\n");
    let mut header = Vec::with_capacity(13);
    header.extend_from_slice(&width.to_be_bytes());
    header.extend_from_slice(&height.to_be_bytes());
    // 8 bits per sample, colour type 2 (RGB), deflate, adaptive filtering method, no interlace.
    header.extend_from_slice(&[8, 2, 0, 0, 0]);
    for (kind, data) in [(b"IHDR", header.as_slice()), (b"IDAT", idat.as_slice()), (b"IEND", &[][..])] {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        let mut crc = flate2::Crc::new();
        crc.update(kind);
        crc.update(data);
        out.extend_from_slice(&crc.sum().to_be_bytes());
    }
    out
}

/// Finite (and, for log axes, positive) value usable on the y axis.
fn y_ok(y: f64, log_y: bool) -> bool {
    y.is_finite() && (!log_y || y > 0.0)
}

/// Data ranges over the usable points of a panel.
fn panel_ranges(p: &Panel<'_>) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for s in &p.series {
        for (&x, &y) in s.x.iter().zip(s.y) {
            if x.is_finite() && y_ok(y, p.log_y) {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    if x0 > x1 {
        // No usable data: fall back to marker positions or a unit range.
        for m in &p.markers {
            if m.x.is_finite() {
                x0 = x0.min(m.x);
                x1 = x1.max(m.x);
            }
        }
        if x0 > x1 {
            x0 = 0.0;
            x1 = 1.0;
        }
    }
    if x0 == x1 {
        let d = if x0 == 0.0 { 1.0 } else { x0.abs() * 0.5 };
        x0 -= d;
        x1 += d;
    }
    if y0 > y1 {
        if p.log_y {
            y0 = 1.0;
            y1 = 10.0;
        } else {
            y0 = 0.0;
            y1 = 1.0;
        }
    } else if p.log_y {
        // Pad by a factor in log space.
        let (l0, l1) = (y0.log10(), y1.log10());
        let pad = ((l1 - l0) * 0.05).max(0.1);
        y0 = 10f64.powf(l0 - pad);
        y1 = 10f64.powf(l1 + pad);
    } else if y0 == y1 {
        let d = if y0 == 0.0 { 1.0 } else { y0.abs() * 0.5 };
        y0 -= d;
        y1 += d;
    } else {
        let pad = (y1 - y0) * 0.05;
        y0 -= pad;
        y1 += pad;
    }
    ((x0, x1), (y0, y1))
}

fn snap_to_zero(v: f64, tiny: f64) -> f64 {
    if v.abs() < tiny {
        0.0
    } else {
        v
    }
}

/// Compact tick label.
fn fmt_num(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        return s.replace(".0e", "e");
    }
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

type Root<'b> = DrawingArea<BitMapBackend<'b>, Shift>;

fn draw_panel<'b>(root: &Root<'b>, area: &Root<'b>, p: &Panel<'_>) -> Result<(), PlotError> {
    let ((x0, x1), (y0, y1)) = panel_ranges(p);
    if p.log_y {
        draw_panel_with(root, area, p, x0..x1, (y0..y1).log_scale())
    } else {
        draw_panel_with(root, area, p, x0..x1, y0..y1)
    }
}

fn draw_panel_with<'b, YR>(
    root: &Root<'b>,
    area: &Root<'b>,
    p: &Panel<'_>,
    xr: std::ops::Range<f64>,
    yr: YR,
) -> Result<(), PlotError>
where
    YR: AsRangedCoord<Value = f64>,
    YR::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 18).into_font().color(&BLACK))
        .margin(8)
        .margin_right(20)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(xr.clone(), yr)
        .map_err(err)?;

    // A tick at zero can come out of the range arithmetic as ±2e-16: label it 0.
    let (xs, ys) = (chart.x_range(), chart.y_range());
    let x_tiny = 1e-9 * xs.start.abs().max(xs.end.abs());
    let y_tiny = if p.log_y { 0.0 } else { 1e-9 * ys.start.abs().max(ys.end.abs()) };
    chart
        .configure_mesh()
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(210, 210, 210))
        .axis_style(BLACK)
        .x_desc(p.x_label.as_str())
        .y_desc(p.y_label.as_str())
        .x_labels(10)
        .y_labels(8)
        .x_label_formatter(&|v| fmt_num(snap_to_zero(*v, x_tiny)))
        .y_label_formatter(&|v| fmt_num(snap_to_zero(*v, y_tiny)))
        .label_style(("sans-serif", 13).into_font().color(&BLACK))
        .axis_desc_style(("sans-serif", 15).into_font().color(&BLACK))
        .draw()
        .map_err(err)?;

    // Shaded spans, behind the data, in pixel space over the whole plotting height.
    let (_, py) = chart.plotting_area().get_pixel_range();
    for &(a, b) in &p.spans {
        let (a, b) = (a.max(xr.start), b.min(xr.end));
        if a < b {
            let (xa, _) = chart.backend_coord(&(a, 1.0));
            let (xb, _) = chart.backend_coord(&(b, 1.0));
            root.draw(&Rectangle::new([(xa, py.start), (xb.max(xa + 1), py.end - 1)], SPAN_COLOR.filled()))
                .map_err(err)?;
        }
    }

    let log_y = p.log_y;
    // Palette colours go by position; what was observed is drawn last, over the models.
    let order = draw_order(&p.series);
    for si in order {
        let s = &p.series[si];
        let color = PALETTE[si % PALETTE.len()];
        let (color, alpha) = match s.look {
            Look::Observed => (OBSERVED_COLOR, 1.0),
            Look::Model => (color, 0.75),
            Look::Line | Look::Points => (color, 1.0),
        };
        let style = color.mix(alpha).stroke_width(2);
        if s.look == Look::Points {
            let points = s.x.iter().zip(s.y).filter(|(x, y)| x.is_finite() && y_ok(**y, log_y));
            chart.draw_series(points.map(|(&x, &y)| Circle::new((x, y), 4, color.mix(0.6).filled()))).map_err(err)?;
        } else {
            // Split into runs of usable points so NaNs (and non-positive values
            // on a log axis) break the line.
            let mut segments: Vec<Vec<(f64, f64)>> = Vec::new();
            let mut cur: Vec<(f64, f64)> = Vec::new();
            for (&x, &y) in s.x.iter().zip(s.y) {
                if x.is_finite() && y_ok(y, log_y) {
                    cur.push((x, y));
                } else if !cur.is_empty() {
                    segments.push(std::mem::take(&mut cur));
                }
            }
            if !cur.is_empty() {
                segments.push(cur);
            }
            for seg in segments {
                if seg.len() == 1 {
                    chart.draw_series(std::iter::once(Circle::new(seg[0], 2, color.filled()))).map_err(err)?;
                } else {
                    // Very dense lines look jagged with a 2 px stroke (plotters draws
                    // wide polylines as separate quads); use 1 px for those, and for models.
                    let plot_w = (chart.plotting_area().dim_in_pixel().0).max(1) as usize;
                    let w = if seg.len() > 2 * plot_w || s.look == Look::Model { 1 } else { 2 };
                    chart.draw_series(LineSeries::new(seg, color.mix(alpha).stroke_width(w))).map_err(err)?;
                }
            }
        }
        // Legend entry (drawn as an empty series so it exists even without data).
        if !s.label.is_empty() {
            let points = s.look == Look::Points;
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(err)?
                .label(s.label.as_str())
                .legend(move |(x, y)| -> DynElement<'static, BitMapBackend<'_>, (i32, i32)> {
                    if points {
                        Circle::new((x + 10, y), 4, style.color.filled()).into_dyn()
                    } else {
                        PathElement::new(vec![(x, y), (x + 20, y)], style).into_dyn()
                    }
                });
        }
    }

    // Markers: vertical dashed lines drawn in pixel space on the root area.
    let label_font = ("sans-serif", 13).into_font().color(&MARKER_COLOR);
    let shown: Vec<&Marker> =
        p.markers.iter().filter(|m| m.x.is_finite() && m.x >= xr.start && m.x <= xr.end).collect();
    let spans: Vec<(i32, i32)> = shown
        .iter()
        .map(|m| {
            let (mx, _) = chart.backend_coord(&(m.x, 1.0)); // y is irrelevant for the x pixel
            let width = if m.label.is_empty() {
                0
            } else {
                root.estimate_text_size(&m.label, &label_font).map_or(0, |s| s.0 as i32)
            };
            (mx + 4, width)
        })
        .collect();
    let rows = label_rows(&spans, LABEL_GAP_PX, MAX_LABEL_ROWS);
    for ((m, row), (label_x, _)) in shown.iter().zip(rows).zip(&spans) {
        let mx = label_x - 4;
        let (dash, gap) = (6, 4);
        let mut y = py.start;
        while y < py.end {
            let ye = (y + dash).min(py.end - 1);
            root.draw(&PathElement::new(vec![(mx, y), (mx, ye)], MARKER_COLOR.stroke_width(1))).map_err(err)?;
            y += dash + gap;
        }
        if let (false, Some(row)) = (m.label.is_empty(), row) {
            let ty = py.start + 4 + row as i32 * LABEL_ROW_PX;
            root.draw(&Text::new(m.label.clone(), (*label_x, ty), label_font.clone())).map_err(err)?;
        }
    }

    if p.series.iter().any(|s| !s.label.is_empty()) {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .label_font(("sans-serif", 13).into_font().color(&BLACK))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// Marker labels stack in up to this many rows below the panel's top; a label that fits in none
/// is left out (its dashed line stays).
const MAX_LABEL_ROWS: usize = 4;
const LABEL_ROW_PX: i32 = 16;
const LABEL_GAP_PX: i32 = 6;

/// The indices of `series` in drawing order: every other series in its order, then the
/// observed ones, so a measurement is never hidden under a model.
fn draw_order(series: &[Series<'_>]) -> Vec<usize> {
    let (observed, others): (Vec<usize>, Vec<usize>) =
        (0..series.len()).partition(|&i| series[i].look == Look::Observed);
    others.into_iter().chain(observed).collect()
}

/// Rows for labels starting at pixel `x` with a `width` (in any order): each label goes in the
/// first row where it starts `gap` pixels after the end of every label already there, else
/// nowhere (None). Labels of width 0 need no row.
fn label_rows(labels: &[(i32, i32)], gap: i32, max_rows: usize) -> Vec<Option<usize>> {
    let mut order: Vec<usize> = (0..labels.len()).collect();
    order.sort_by_key(|&i| (labels[i].0, i));
    let mut row_ends: Vec<i32> = Vec::new();
    let mut rows = vec![None; labels.len()];
    for i in order {
        let (x, width) = labels[i];
        if width == 0 {
            continue;
        }
        match row_ends.iter().position(|&end| x >= end + gap) {
            Some(row) => {
                row_ends[row] = x + width;
                rows[i] = Some(row);
            }
            None if row_ends.len() < max_rows => {
                row_ends.push(x + width);
                rows[i] = Some(row_ends.len() - 1);
            }
            None => {}
        }
    }
    rows
}

/// Angles in degrees made continuous: each sample moved by whole turns to lie within 180° of
/// the one before, so a caster turning past ±180° draws as a turn, not a jump across the plot.
pub fn unwrap_degrees(angles: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(angles.len());
    let mut previous: Option<f64> = None;
    for &a in angles {
        let value = match previous {
            Some(p) if a.is_finite() => a - 360.0 * ((a - p) / 360.0).round(),
            _ => a,
        };
        if value.is_finite() {
            previous = Some(value);
        }
        out.push(value);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The messages stages and users read, as they were when these errors were strings.
    #[test]
    fn errors_say_what_is_wrong_with_the_figure() {
        assert_eq!(render_png("t", &[], 8, 100).unwrap_err().to_string(), "figure size 8x100 is too small");
        let side = Panel::default();
        assert_eq!(
            render_png_with_side("t", &[], &side, 100, 110, 100).unwrap_err().to_string(),
            "figure size 110x100 with a 100 px side panel is too small"
        );
        let panel = Panel { series: vec![Series::new("s", &[1.0, 2.0], &[1.0])], ..Panel::default() };
        assert_eq!(
            render_png("t", &[panel], 100, 100).unwrap_err().to_string(),
            "panel 0 series 's': x has 2 points but y has 1"
        );
        assert_eq!(err("backend").to_string(), "plot error: \"backend\"");
    }

    fn figure_bytes() -> Vec<u8> {
        let fs = 200.0;
        let n = (60.0 * fs) as usize;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / fs).collect();
        let a: Vec<f64> = t
            .iter()
            .map(|&t| (2.0 * std::f64::consts::PI * 0.2 * t).sin() + 0.3 * (2.0 * std::f64::consts::PI * 3.1 * t).sin())
            .collect();
        let mut b: Vec<f64> = t.iter().map(|&t| 0.7 * (2.0 * std::f64::consts::PI * 0.5 * t + 1.0).cos()).collect();
        // A NaN gap to exercise line breaking.
        for v in &mut b[4000..4200] {
            *v = f64::NAN;
        }
        let f: Vec<f64> = (0..=400).map(|i| i as f64 * 0.05).collect();
        let spec: Vec<f64> =
            f.iter().map(|&f| 1e-4 + 1.0 / (1.0 + ((f - 3.1) / 0.15).powi(2)) + 0.1 / (1.0 + f * f)).collect();
        let mut spec2: Vec<f64> = spec.iter().map(|v| v * 0.3).collect();
        spec2[0] = 0.0; // non-positive: skipped on log axis
        let panels = vec![
            Panel {
                title: "Time history".into(),
                x_label: "time [s]".into(),
                y_label: "amplitude [m]".into(),
                series: vec![Series::new("heave", &t, &a).model(), Series::new("pitch", &t, &b).observed()],
                markers: vec![],
                log_y: false,
                spans: vec![(10.0, 20.0)],
            },
            Panel {
                title: "Spectrum".into(),
                x_label: "frequency [Hz]".into(),
                y_label: "PSD [m²/Hz]".into(),
                series: vec![Series::new("heave PSD", &f, &spec), Series::new("pitch PSD", &f, &spec2).points()],
                markers: vec![Marker { x: 3.1, label: "f₀ = 3.1 Hz".into() }],
                log_y: true,
                spans: vec![],
            },
        ];
        render_png("Test figure", &panels, 1000, 800).expect("render")
    }

    #[test]
    fn renders_deterministic_nonblank_png() {
        let png1 = figure_bytes();
        let png2 = figure_bytes();
        assert_eq!(png1, png2, "output not deterministic");
        std::fs::write("/tmp/plot-test.png", &png1).unwrap();

        let dec = png::Decoder::new(png1.as_slice());
        let mut reader = dec.read_info().unwrap();
        let mut img = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut img).unwrap();
        assert_eq!((info.width, info.height), (1000, 800));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        let px = &img[..info.buffer_size()];
        // Compressed as FIGURE_COMPRESSION chooses: zlib level 1, unfiltered, leaves ~6 % of the
        // pixels here (146 KB of 2.4 MB; the png crate's fastest mode leaves ~25 %).
        assert!(png1.len() * 12 < px.len(), "{} bytes for {} bytes of pixels", png1.len(), px.len());
        // Every filter decodes to the same pixels.
        for filter in [RowFilter::None, RowFilter::Sub, RowFilter::Up] {
            let again = encode_rgb_png(px, info.width, info.height, 1, filter);
            let mut reader = png::Decoder::new(again.as_slice()).read_info().unwrap();
            let mut pixels = vec![0; reader.output_buffer_size()];
            reader.next_frame(&mut pixels).unwrap();
            assert!(pixels == px, "{filter:?} changes the pixels");
        }
        let mut colors = std::collections::BTreeSet::new();
        for c in px.chunks_exact(3) {
            colors.insert((c[0], c[1], c[2]));
        }
        assert!(colors.len() > 10, "only {} colours", colors.len());
        for c in [PALETTE[0], OBSERVED_COLOR] {
            assert!(colors.contains(&(c.0, c.1, c.2)), "series colour {c:?} missing");
        }
    }

    #[test]
    fn marker_labels_never_overlap_in_a_row() {
        // Ten impacts in two seconds, labels 60-90 px wide and 15-40 px apart: the old stagger
        // (three rows by index) overlapped them.
        let labels: Vec<(i32, i32)> = (0..10).map(|i| (100 + i * 15 + (i % 3) * 25, 60 + (i % 4) * 10)).collect();
        let rows = label_rows(&labels, LABEL_GAP_PX, MAX_LABEL_ROWS);
        for i in 0..labels.len() {
            for j in 0..i {
                if let (Some(a), Some(b)) = (rows[i], rows[j]) {
                    let (lo, hi) =
                        if labels[i].0 < labels[j].0 { (labels[i], labels[j]) } else { (labels[j], labels[i]) };
                    assert!(a != b || lo.0 + lo.1 + LABEL_GAP_PX <= hi.0, "labels {i} and {j} overlap in row {a}");
                }
            }
        }
        assert!(rows.iter().flatten().all(|&r| r < MAX_LABEL_ROWS));
        // A label is left out only when it overlaps a placed label in every row.
        let overlaps = |a: (i32, i32), b: (i32, i32)| a.0 < b.0 + b.1 + LABEL_GAP_PX && b.0 < a.0 + a.1 + LABEL_GAP_PX;
        for (i, row) in rows.iter().enumerate().filter(|(_, r)| r.is_none()) {
            for r in 0..MAX_LABEL_ROWS {
                let blocked = (0..labels.len()).any(|j| rows[j] == Some(r) && overlaps(labels[i], labels[j]));
                assert!(blocked, "label {i} ({row:?}) would fit in row {r}: {rows:?}");
            }
        }
        assert_eq!(rows.iter().flatten().count(), 7, "{rows:?}");
        // Far apart, they all sit in the first row.
        assert_eq!(label_rows(&[(0, 50), (100, 50), (200, 50)], 6, 4), [Some(0), Some(0), Some(0)]);
        assert_eq!(label_rows(&[(0, 0), (0, 50)], 6, 4), [None, Some(0)], "an empty label takes no room");
    }

    #[test]
    fn observed_series_are_drawn_after_the_models() {
        let v = [0.0, 1.0];
        let series = [
            Series::new("observed", &v, &v).observed(),
            Series::new("model", &v, &v).model(),
            Series::new("floor", &v, &v),
        ];
        assert_eq!(draw_order(&series), [1, 2, 0]);
    }

    #[test]
    fn unwrapped_angles_turn_instead_of_jumping() {
        let wrapped = [170.0, 179.0, -179.0, -170.0, 175.0, f64::NAN, -175.0, 10.0];
        let unwrapped = unwrap_degrees(&wrapped);
        assert_eq!(&unwrapped[..5], [170.0, 179.0, 181.0, 190.0, 175.0]);
        assert!(unwrapped[5].is_nan());
        assert_eq!(unwrapped[6], 185.0, "continues from the last finite angle");
        assert_eq!(unwrapped[7], 10.0, "175° back is a turn back");
        for (a, w) in unwrapped.iter().zip(&wrapped) {
            assert!(a.is_nan() || ((a - w) / 360.0).fract() == 0.0, "moved by whole turns only");
        }
    }

    #[test]
    fn a_side_panel_keeps_its_data_in_view_with_equal_scales() {
        // An ellipse 4 × 2 m in a tall side panel: both axes get the same metres per pixel, and
        // the whole ellipse stays in view.
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 0.0314).collect();
        let (x, y): (Vec<f64>, Vec<f64>) = t.iter().map(|a| (2.0 * a.cos(), a.sin())).unzip();
        let orbit = Panel {
            title: "orbit".into(),
            x_label: "x [m]".into(),
            y_label: "y [m]".into(),
            series: vec![Series::new("path", &x, &y)],
            markers: vec![],
            log_y: false,
            spans: Vec::new(),
        };
        let ((x0, x1), (y0, y1)) = equal_aspect_ranges(&orbit, (400, 700));
        assert!(((x1 - x0) / (400.0 - 98.0) - (y1 - y0) / (700.0 - 90.0)).abs() < 1e-12);
        let lo = |v: &[f64]| v.iter().fold(f64::INFINITY, |m, &a| m.min(a));
        let hi = |v: &[f64]| v.iter().fold(f64::NEG_INFINITY, |m, &a| m.max(a));
        assert!(x0 <= lo(&x) && x1 >= hi(&x) && y0 <= lo(&y) && y1 >= hi(&y));
        let stack = || Panel {
            title: "t".into(),
            x_label: "t".into(),
            y_label: "x".into(),
            series: vec![Series::new("x", &t, &x)],
            markers: vec![],
            log_y: false,
            spans: Vec::new(),
        };
        let png = render_png_with_side("figure", &[stack()], &orbit, 400, 1200, 700).unwrap();
        assert!(png.starts_with(b"\x89PNG"));
        assert_eq!(png, render_png_with_side("figure", &[stack()], &orbit, 400, 1200, 700).unwrap(), "deterministic");
        assert!(render_png_with_side("figure", &[stack()], &orbit, 1190, 1200, 700).is_err());
    }

    #[test]
    fn rejects_mismatched_lengths_and_handles_empty() {
        let x = [1.0, 2.0];
        let y = [1.0];
        let p = Panel {
            title: "bad".into(),
            x_label: String::new(),
            y_label: String::new(),
            series: vec![Series::new("s", &x, &y)],
            markers: vec![],
            ..Panel::default()
        };
        assert!(render_png("t", &[p], 200, 200).is_err());
        let nan = [f64::NAN, f64::NAN];
        let p = Panel {
            title: "all nan".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series::new("s", &x, &nan)],
            markers: vec![Marker { x: 1.5, label: "m".into() }],
            log_y: true,
            spans: vec![],
        };
        assert!(render_png("t", &[p], 300, 200).is_ok());
        assert!(render_png("", &[], 100, 100).is_ok());
    }
}
