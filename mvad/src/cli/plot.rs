//! Pictures with plotters, as SVG or PNG (chosen by the file extension).
//!
//! Text is laid out (both formats) and, in PNG, drawn by the pure-Rust `ab_glyph`
//! rasteriser with DejaVu Sans Mono, shipped in `mvad/assets/` (plotters' bitmap
//! backend has no font of its own and would panic without one).
//!
//! Two pictures: [`figure1`] (what the paper's Figure 1 shows: the trajectory with its
//! events, the density with the atoms as stems, MV-AD against FD) and [`workprec`]
//! (error against wall time, log-log).

use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::output::g;
use super::CliError;

/// Tick labels for a linear axis over `range`: 4 significant digits (`2.5e7`, `-0.0013`),
/// so an axis whose scale is far from 1 does not print every tick as `0.0`, and a tick that
/// is zero up to rounding (|v| ≤ 1e-12 of the axis scale) prints as `0`.
fn axis_label(range: &Range<f64>) -> impl Fn(&f64) -> String {
    let scale = range.start.abs().max(range.end.abs());
    move |v: &f64| {
        if v.abs() <= 1e-12 * scale {
            "0".to_string()
        } else {
            g(*v, 4)
        }
    }
}

/// The picture formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Scalable vector graphics.
    Svg,
    /// Portable network graphics.
    Png,
}

/// The format of `path` from its extension (`.svg` or `.png`), or a bad-input error.
pub fn format_of(path: &Path) -> Result<Format, CliError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("svg") => Ok(Format::Svg),
        Some("png") => Ok(Format::Png),
        _ => Err(CliError::Input(format!(
            "error: --plot: `{}` must end in .svg or .png",
            path.display()
        ))),
    }
}

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Registers the shipped font under the family names plotters uses (once).
fn ensure_font() -> Result<(), CliError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        ["sans-serif", "serif", "monospace"]
            .iter()
            .all(|name| plotters::style::register_font(name, FontStyle::Normal, FONT).is_ok())
    });
    if ok {
        Ok(())
    } else {
        Err(CliError::Run(
            "error: the shipped font could not be loaded".into(),
        ))
    }
}

type DrawResult = Result<(), String>;

/// Maps any plotters error to a run failure naming the file.
fn fail(path: &Path, e: impl std::fmt::Display) -> CliError {
    CliError::Run(format!("error: cannot draw `{}`: {e}", path.display()))
}

/// A picture that can be drawn on any plotters backend.
trait Picture {
    /// The size in pixels.
    fn size(&self) -> (u32, u32);
    /// Draws the whole picture on `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult;
}

/// Draws `pic` into `path`, as SVG or PNG by the extension.
fn render(path: &Path, pic: &impl Picture) -> Result<(), CliError> {
    let fmt = format_of(path)?;
    ensure_font()?;
    match fmt {
        Format::Svg => present(path, SVGBackend::new(path, pic.size()), pic),
        Format::Png => present(path, BitMapBackend::new(path, pic.size()), pic),
    }
}

fn present<DB: DrawingBackend>(
    path: &Path,
    backend: DB,
    pic: &impl Picture,
) -> Result<(), CliError> {
    let root = backend.into_drawing_area();
    pic.draw(&root).map_err(|e| fail(path, e))?;
    root.present().map_err(|e| fail(path, e))
}

/// The largest font size ≤ `want` (and ≥ 10) at which `text` fits the width of `area`
/// with 10 px to spare on each side.
fn fitting_size<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, text: &str, want: u32) -> u32 {
    let room = area.dim_in_pixel().0.saturating_sub(20);
    let mut size = want.max(10);
    while size > 10 {
        let width = area
            .estimate_text_size(text, &("sans-serif", size).into_text_style(area))
            .map(|(w, _)| w)
            // A monospace glyph is 0.6 em wide.
            .unwrap_or((text.chars().count() as f64 * 0.6 * f64::from(size)) as u32);
        if width <= room {
            break;
        }
        size -= 1;
    }
    size
}

/// A chart builder on `area` with the caption (shrunk to fit) and the margins every
/// panel uses.
fn panel<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    caption_size: u32,
    y_label_area: u32,
) -> ChartBuilder<'a, 'b, DB> {
    let mut b = ChartBuilder::on(area);
    b.caption(
        caption,
        ("sans-serif", fitting_size(area, caption, caption_size)),
    )
    .margin(10)
    .x_label_area_size(40)
    .y_label_area_size(y_label_area);
    b
}

/// A [`panel`] on `area` over t ∈ `t_range` (x axis "t") and `y_range` (labelled `y_desc`
/// if given, ticks by [`axis_label`]), its mesh drawn.
fn time_panel<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    caption_size: u32,
    t_range: Range<f64>,
    y_range: &Range<f64>,
    y_desc: Option<&str>,
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    let mut chart = panel(area, caption, caption_size, 60)
        .build_cartesian_2d(t_range, y_range.clone())
        .map_err(e)?;
    let ticks = axis_label(y_range);
    let mut mesh = chart.configure_mesh();
    mesh.x_desc("t").y_label_formatter(&ticks);
    if let Some(desc) = y_desc {
        mesh.y_desc(desc);
    }
    mesh.draw().map_err(e)?;
    Ok(chart)
}

/// The polyline `points` cut into pieces that plotters strokes correctly when the line
/// is thicker than one pixel, with `px` mapping a point to its pixel:
/// - a point on the pixel of its predecessor is dropped (a segment of length zero has
///   no direction, and plotters would put a vertex of the outline at NaN, i.e. at 0);
/// - the line is cut where it turns by more than 90° (plotters joins segments with
///   unbounded miters, so a near reversal, such as a jump followed by a slope, would
///   draw a spike across the picture); the two pieces share the corner;
/// - a non-finite point ends a piece.
///
/// Pieces of a single point (nothing to draw) are left out.
fn stroke_pieces(
    points: impl IntoIterator<Item = (f64, f64)>,
    px: impl Fn(&(f64, f64)) -> (i32, i32),
) -> Vec<Vec<(f64, f64)>> {
    let mut pieces = Vec::new();
    let mut piece: Vec<(f64, f64)> = Vec::new();
    // The pixels of the last two points of `piece`.
    let mut before: Option<(i32, i32)> = None;
    let mut last: Option<(i32, i32)> = None;
    let mut finish = |piece: &mut Vec<(f64, f64)>| {
        let done = std::mem::take(piece);
        if done.len() >= 2 {
            pieces.push(done);
        }
    };
    for p in points {
        if !(p.0.is_finite() && p.1.is_finite()) {
            finish(&mut piece);
            (before, last) = (None, None);
            continue;
        }
        let q = px(&p);
        if last == Some(q) {
            continue;
        }
        if let (Some(a), Some(b)) = (before, last) {
            let turn = i64::from(b.0 - a.0) * i64::from(q.0 - b.0)
                + i64::from(b.1 - a.1) * i64::from(q.1 - b.1);
            if turn < 0 {
                let corner = piece[piece.len() - 1];
                finish(&mut piece);
                piece.push(corner);
            }
        }
        piece.push(p);
        (before, last) = (last, Some(q));
    }
    finish(&mut piece);
    pieces
}

/// How a line is stroked.
#[derive(Clone, Copy, Debug)]
enum Stroke {
    /// A solid line.
    Solid,
    /// Dashes of this many pixels with gaps of that many.
    Dashed(u32, u32),
}

/// Draws `points` as a line in `style` cut into [`stroke_pieces`], with a legend entry
/// if `label` is given.
fn line<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    points: impl IntoIterator<Item = (f64, f64)>,
    style: ShapeStyle,
    stroke: Stroke,
    label: Option<&str>,
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate<From = (f64, f64)>,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let pieces = stroke_pieces(points, |p| chart.as_coord_spec().translate(p));
    for piece in pieces {
        match stroke {
            Stroke::Solid => chart.draw_series(std::iter::once(PathElement::new(piece, style))),
            Stroke::Dashed(dash, gap) => {
                chart.draw_series(DashedLineSeries::new(piece, dash, gap, style))
            }
        }
        .map_err(err)?;
    }
    if let Some(label) = label {
        // An empty series that only puts the entry in the legend.
        chart
            .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
    }
    Ok(())
}

/// Draws the legend box of `chart` at `pos`.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    pos: SeriesLabelPosition,
) -> DrawResult {
    chart
        .configure_series_labels()
        .position(pos)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())
}

/// A finite range covering `values`, padded by 5% (and never empty).
pub fn span(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.into_iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return -1.0..1.0;
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        0.5 * lo.abs().max(1e-12)
    };
    (lo - pad)..(hi + pad)
}

/// Whole decades `(a, b)`, a < b, such that 10^a ≤ v ≤ 10^b for every finite v ≥ `floor`
/// in `values`; `None` if there is no such value.
pub fn decades(values: impl IntoIterator<Item = f64>, floor: f64) -> Option<(i32, i32)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values
        .into_iter()
        .filter(|v| v.is_finite() && *v >= floor && *v > 0.0)
    {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return None;
    }
    // The exponents of f64 lie in [−324, 309]: the casts cannot overflow.
    let a = lo.log10().floor() as i32;
    let b = (hi.log10().ceil() as i32).max(a + 1);
    Some((a, b))
}

/// 10^e, correctly rounded (`powi` is off by ulps for large |e|).
fn pow10(e: i32) -> f64 {
    format!("1e{e}").parse().unwrap_or(f64::NAN)
}

/// The labelled ticks of a log axis over the decades a..=b: every decade, or every
/// k-th one when there are more than seven, so that labels never crowd.
pub fn decade_ticks(a: i32, b: i32) -> Vec<f64> {
    let stride = ((b - a) as usize).div_ceil(6).max(1);
    (a..=b).step_by(stride).map(pow10).collect()
}

/// A log axis over the decades a..=b, labelled at [`decade_ticks`] only; light grid
/// lines at 2…9 × 10^k when the axis spans at most four decades, else at every decade.
fn log_axis(a: i32, b: i32) -> WithKeyPoints<LogCoord<f64>> {
    let light: Vec<f64> = if b - a <= 4 {
        (a..b)
            .flat_map(|e| (2..10).map(move |m| f64::from(m) * pow10(e)))
            .collect()
    } else {
        (a..=b).map(pow10).collect()
    };
    (pow10(a)..pow10(b))
        .log_scale()
        .with_key_points(decade_ticks(a, b))
        .with_light_points(light)
}

/// The label of a decade tick: `1e-14`.
fn decade_label(v: &f64) -> String {
    format!("1e{}", v.log10().round())
}

/// The data of Figure 1 for one observable y and one parameter θ.
#[derive(Clone, Debug, Default)]
pub struct Figure1 {
    /// Heading of the whole picture.
    pub title: String,
    /// Name of the observable y.
    pub observable: String,
    /// Name of the parameter θ.
    pub param: String,
    /// (t, y(t)) samples.
    pub trajectory: Vec<(f64, f64)>,
    /// Event times.
    pub events: Vec<f64>,
    /// (t, density h_x S + h_θ for θ) samples.
    pub density: Vec<(f64, f64)>,
    /// (t_k, α_k for θ).
    pub atoms: Vec<(f64, f64)>,
    /// (t, d/dθ ∫₀ᵗ y ds) from MV-AD (density integral plus atoms so far).
    pub cumulative_mvad: Vec<(f64, f64)>,
    /// (t, d/dθ ∫₀ᵗ y ds) by central finite differences.
    pub cumulative_fd: Vec<(f64, f64)>,
    /// A line of numbers for the bottom panel (MV-AD, FD, errors).
    pub note: String,
}

/// Draws Figure 1 into `path` (.svg or .png).
pub fn figure1(path: &Path, fig: &Figure1) -> Result<(), CliError> {
    render(path, fig)
}

impl Picture for Figure1 {
    fn size(&self) -> (u32, u32) {
        (1200, 900)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        let fig = self;
        let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
        root.fill(&WHITE).map_err(e)?;
        let root = root
            .titled(
                &fig.title,
                ("sans-serif", fitting_size(root, &fig.title, 24)),
            )
            .map_err(e)?;
        let (top, bottom) = root.split_vertically(root.dim_in_pixel().1 / 2);
        let (tl, tr) = top.split_horizontally(top.dim_in_pixel().0 / 2);

        // Top left: y(t) with the events as red dashed lines.
        let t_range = span(fig.trajectory.iter().map(|p| p.0));
        let y_range = span(fig.trajectory.iter().map(|p| p.1));
        {
            let caption = format!("{}(t) and events", fig.observable);
            let y_desc = Some(fig.observable.as_str());
            let mut chart = time_panel(&tl, &caption, 18, t_range.clone(), &y_range, y_desc)?;
            let trajectory = fig.trajectory.iter().copied();
            line(
                &mut chart,
                trajectory,
                BLUE.stroke_width(2),
                Stroke::Solid,
                None,
            )?;
            for &tk in &fig.events {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(tk, y_range.start), (tk, y_range.end)],
                        6,
                        4,
                        RED.stroke_width(1),
                    ))
                    .map_err(e)?;
            }
        }

        // Top right: density (line) and atoms (stems with a dot).
        {
            let d_range = span(
                fig.density
                    .iter()
                    .map(|p| p.1)
                    .chain(fig.atoms.iter().map(|a| a.1))
                    .chain(std::iter::once(0.0)),
            );
            // Headroom for the legend in the upper right corner.
            let d_range = d_range.start..d_range.end + 0.25 * (d_range.end - d_range.start);
            let caption = format!("d{}/d{}: density and atoms", fig.observable, fig.param);
            let mut chart = time_panel(&tr, &caption, 18, t_range.clone(), &d_range, None)?;
            let density = fig.density.iter().copied();
            let blue = BLUE.stroke_width(2);
            line(&mut chart, density, blue, Stroke::Solid, Some("density"))?;
            for &(tk, a) in &fig.atoms {
                let stem = [(tk, 0.0), (tk, a)];
                line(&mut chart, stem, RED.stroke_width(2), Stroke::Solid, None)?;
            }
            chart
                .draw_series(
                    fig.atoms
                        .iter()
                        .map(|&(tk, a)| Circle::new((tk, a), 5, RED.filled())),
                )
                .map_err(e)?
                .label("atoms")
                .legend(|(x, y)| Circle::new((x + 10, y), 5, RED.filled()));
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }

        // Bottom: d/dθ ∫₀ᵗ y ds, MV-AD against FD; the caption on two lines (the
        // comparison's numbers below the heading), each shrunk to fit.
        {
            let heading = format!(
                "d/d{} of ∫ {} ds over [0, t]: MV-AD vs central FD",
                fig.param, fig.observable
            );
            let bottom = bottom
                .titled(
                    &heading,
                    ("sans-serif", fitting_size(&bottom, &heading, 18)),
                )
                .map_err(e)?;
            let c_range = span(
                fig.cumulative_mvad
                    .iter()
                    .chain(&fig.cumulative_fd)
                    .map(|p| p.1),
            );
            let mut chart = time_panel(&bottom, &fig.note, 15, t_range, &c_range, None)?;
            let mvad = fig.cumulative_mvad.iter().copied();
            line(
                &mut chart,
                mvad,
                BLUE.stroke_width(3),
                Stroke::Solid,
                Some("MV-AD"),
            )?;
            let fd = fig.cumulative_fd.iter().copied();
            let red = RED.stroke_width(2);
            line(
                &mut chart,
                fd,
                red,
                Stroke::Dashed(8, 5),
                Some("central FD"),
            )?;
            legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        }
        Ok(())
    }
}

/// One curve of a work-precision picture: (wall seconds, error) points.
#[derive(Clone, Debug, Default)]
pub struct Curve {
    /// Legend text.
    pub label: String,
    /// (wall seconds, error) points, in tolerance order. Errors below [`ERROR_FLOOR`]
    /// (an exact 0 included) are drawn on the bottom edge (a decade below the
    /// smallest resolved error) as triangles, and
    /// the panel's legend says so; points with a non-finite or non-positive time or a
    /// non-finite error are left out.
    pub points: Vec<(f64, f64)>,
}

/// Errors below this are not resolved by a log axis of doubles: they sit on the floor.
pub const ERROR_FLOOR: f64 = 1e-17;

/// Work-precision panels (one per quantity, side by side).
struct WorkPrec<'a> {
    title: &'a str,
    panels: &'a [(String, Vec<Curve>)],
}

/// Draws work-precision panels (one per quantity, side by side) log-log into `path`.
pub fn workprec(path: &Path, title: &str, panels: &[(String, Vec<Curve>)]) -> Result<(), CliError> {
    render(path, &WorkPrec { title, panels })
}

impl Picture for WorkPrec<'_> {
    fn size(&self) -> (u32, u32) {
        (600 * self.panels.len().clamp(1, 8) as u32, 500)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult {
        let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
        root.fill(&WHITE).map_err(e)?;
        let root = root
            .titled(
                self.title,
                ("sans-serif", fitting_size(root, self.title, 22)),
            )
            .map_err(e)?;
        let areas = root.split_evenly((1, self.panels.len().max(1)));
        let colors = [
            BLUE,
            RED,
            GREEN,
            MAGENTA,
            CYAN,
            BLACK,
            RGBColor(230, 140, 0),
            RGBColor(120, 60, 160),
        ];
        for ((name, curves), area) in self.panels.iter().zip(areas.iter()) {
            let kept = |c: &Curve| -> Vec<(f64, f64)> {
                c.points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.0 > 0.0 && p.1.is_finite())
                    .collect()
            };
            let all: Vec<(f64, f64)> = curves.iter().flat_map(kept).collect();
            let (xa, xb) = decades(all.iter().map(|p| p.0), 0.0).unwrap_or((-6, 0));
            let (ya, yb) = decades(all.iter().map(|p| p.1), ERROR_FLOOR).unwrap_or((-17, -15));
            // A decade of headroom for the legend in the upper right corner, and one
            // below the smallest resolved error for the floor, when a point needs it.
            let yb = yb + 1;
            let any_floored = all.iter().any(|p| p.1 < ERROR_FLOOR);
            let ya = if any_floored { ya - 1 } else { ya };
            let floor = pow10(ya);
            let mut chart = panel(area, name, 18, 60)
                .build_cartesian_2d(log_axis(xa, xb), log_axis(ya, yb))
                .map_err(e)?;
            chart
                .configure_mesh()
                .x_desc("wall time (s)")
                .y_desc("error")
                .x_label_formatter(&decade_label)
                .y_label_formatter(&decade_label)
                .draw()
                .map_err(e)?;
            for (i, c) in curves.iter().enumerate() {
                let color = colors[i % colors.len()];
                let pts = kept(c)
                    .into_iter()
                    .map(|(x, y)| (x, if y < ERROR_FLOOR { floor } else { y }));
                let style = color.stroke_width(2);
                line(&mut chart, pts, style, Stroke::Solid, Some(&c.label))?;
                let resolved = kept(c).into_iter().filter(|p| p.1 >= ERROR_FLOOR);
                chart
                    .draw_series(resolved.map(|p| Circle::new(p, 4, color.filled())))
                    .map_err(e)?;
                let floored: Vec<(f64, f64)> = kept(c)
                    .into_iter()
                    .filter(|p| p.1 < ERROR_FLOOR)
                    .map(|p| (p.0, floor))
                    .collect();
                chart
                    .draw_series(
                        floored
                            .into_iter()
                            .map(|p| TriangleMarker::new(p, 7, color.stroke_width(2))),
                    )
                    .map_err(e)?;
            }
            if any_floored {
                // An empty series that only puts its entry in the legend.
                chart
                    .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                    .map_err(e)?
                    .label(format!("error < {ERROR_FLOOR:.0e} (or 0): on the floor"))
                    .legend(|(x, y)| TriangleMarker::new((x + 10, y), 7, BLACK.stroke_width(2)));
            }
            legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_figure() -> Figure1 {
        let ts: Vec<f64> = (0..=200).map(|i| i as f64 * 0.01).collect();
        Figure1 {
            title: "test".into(),
            observable: "height".into(),
            param: "e".into(),
            trajectory: ts.iter().map(|&t| (t, (2.0 - t * t).abs())).collect(),
            events: vec![0.6, 1.6],
            density: ts.iter().map(|&t| (t, t.sin())).collect(),
            atoms: vec![(0.6, 1.0), (1.6, -0.5)],
            cumulative_mvad: ts.iter().map(|&t| (t, t)).collect(),
            cumulative_fd: ts.iter().map(|&t| (t, t + 1e-3)).collect(),
            note: "MV-AD 1, FD 1".into(),
        }
    }

    fn scratch() -> tempfile::TempDir {
        crate::cli::test_support::scratch_dir("plot")
    }

    #[test]
    fn figure1_svg_and_png() {
        let dir = scratch();
        let fig = sample_figure();
        let svg = dir.path().join("fig.svg");
        figure1(&svg, &fig).expect("svg");
        let text = std::fs::read_to_string(&svg).expect("written");
        assert!(text.starts_with("<svg"), "{}", &text[..50.min(text.len())]);
        assert!(text.contains("density and atoms"));
        let png = dir.path().join("fig.png");
        figure1(&png, &fig).expect("png");
        let bytes = std::fs::read(&png).expect("written");
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }

    #[test]
    fn workprec_svg_and_png() {
        let dir = scratch();
        let curves = vec![
            Curve {
                label: "MV-AD".into(),
                points: vec![(1e-4, 1e-3), (2e-4, 1e-6), (5e-4, 0.0)],
            },
            Curve {
                label: "FD".into(),
                points: vec![(2e-4, 1e-2), (4e-4, 1e-5), (f64::NAN, 1.0)],
            },
        ];
        let panels = vec![
            ("C".to_string(), curves.clone()),
            ("dC/de".to_string(), curves),
        ];
        let svg = dir.path().join("wp.svg");
        workprec(&svg, "wp", &panels).expect("svg");
        let text = std::fs::read_to_string(&svg).expect("written");
        // The exact zero sits on the floor, and the legend says so; labels are decades.
        assert!(text.contains("on the floor"), "no floor legend");
        let labels: Vec<&str> = text.lines().filter(|l| l.parse::<f64>().is_ok()).collect();
        assert!(
            labels.contains(&"1e-6") && labels.contains(&"1e-4"),
            "{labels:?}"
        );
        assert!(
            labels.iter().all(|l| l.starts_with("1e")),
            "a label that is not a decade: {labels:?}"
        );
        workprec(&dir.path().join("wp.png"), "wp", &panels).expect("png");
        // Without a floored point there is no floor entry.
        let clean = vec![("C".to_string(), vec![panels[0].1[1].clone()])];
        workprec(&svg, "wp", &clean).expect("svg");
        let text = std::fs::read_to_string(&svg).expect("written");
        assert!(!text.contains("on the floor"));
    }

    #[test]
    fn bad_paths_are_errors_not_panics() {
        let dir = scratch();
        assert_eq!(
            format_of(Path::new("a.pdf")).err().map(|e| e.status()),
            Some(2)
        );
        assert_eq!(
            format_of(Path::new("noext")).err().map(|e| e.status()),
            Some(2)
        );
        let fig = sample_figure();
        let err = figure1(Path::new("/nonexistent-dir/x/fig.png"), &fig).err();
        assert_eq!(err.map(|e| e.status()), Some(1));
        let err = figure1(Path::new("/nonexistent-dir/x/fig.svg"), &fig).err();
        assert_eq!(err.map(|e| e.status()), Some(1));
        // Degenerate data: empty and non-finite series.
        let empty = Figure1::default();
        figure1(&dir.path().join("empty.svg"), &empty).expect("empty figure draws");
    }

    #[test]
    fn spans_are_finite_and_nonempty() {
        let r = span([1.0, f64::NAN, 1.0]);
        assert!(r.start < r.end && r.start.is_finite());
        let r = span([]);
        assert!(r.start < r.end);
    }

    #[test]
    fn thick_lines_are_cut_at_reversals_and_lose_repeated_pixels() {
        let px = |p: &(f64, f64)| (p.0 as i32, p.1 as i32);
        // A sawtooth: up, a jump down, up again; the jump reverses the direction twice.
        let saw = [(0.0, 0.0), (10.0, 10.0), (10.2, -40.0), (20.0, -30.0)];
        assert_eq!(
            stroke_pieces(saw, px),
            vec![
                vec![(0.0, 0.0), (10.0, 10.0)],
                vec![(10.0, 10.0), (10.2, -40.0)],
                vec![(10.2, -40.0), (20.0, -30.0)],
            ]
        );
        // A right angle and a straight line stay whole; repeated pixels are dropped.
        let bend = [(0.0, 0.0), (0.4, 0.3), (5.0, 0.0), (5.0, 5.0), (5.0, 9.0)];
        assert_eq!(
            stroke_pieces(bend, px),
            vec![vec![(0.0, 0.0), (5.0, 0.0), (5.0, 5.0), (5.0, 9.0)]]
        );
        // Non-finite points split; lone points and zero-length stems draw nothing.
        let gap = [
            (0.0, 0.0),
            (1.0, 1.0),
            (f64::NAN, 0.0),
            (2.0, 2.0),
            (3.0, 2.0),
        ];
        assert_eq!(stroke_pieces(gap, px).len(), 2);
        assert!(stroke_pieces([(1.0, 0.0), (1.0, 0.0)], px).is_empty());
        assert!(stroke_pieces([(f64::INFINITY, 0.0)], px).is_empty());
    }

    #[test]
    fn log_axes_cover_whole_decades_with_few_labels() {
        assert_eq!(decades([1.1e-3, 3e-3, f64::NAN], 0.0), Some((-3, -2)));
        assert_eq!(decades([8.2e-16, 1.8e-14], ERROR_FLOOR), Some((-16, -13)));
        assert_eq!(decades([1e-3], 0.0), Some((-3, -2)));
        assert_eq!(decades([0.0, 1e-18, -1.0], ERROR_FLOOR), None);
        assert_eq!(decade_ticks(-16, -13), vec![1e-16, 1e-15, 1e-14, 1e-13]);
        for (a, b) in [(-15, -3), (-17, 0), (-300, 300)] {
            let ticks = decade_ticks(a, b);
            assert!(ticks.len() <= 7 && ticks.len() >= 2, "{a}..{b}: {ticks:?}");
            assert_eq!(ticks[0], pow10(a));
        }
        assert_eq!(decade_label(&1e-14), "1e-14");
        assert_eq!(decade_label(&pow10(-3)), "1e-3");
        assert_eq!(decade_label(&1.0), "1e0");
    }
}
