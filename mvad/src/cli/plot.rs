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

use plotters::coord::Shift;
use plotters::prelude::*;

use super::CliError;

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

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSansMono.ttf");

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

/// A positive range for a log axis covering the positive finite `values`.
pub fn log_span(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in values.into_iter().filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || hi <= 0.0 {
        return 1e-16..1.0;
    }
    if hi <= lo {
        return (lo / 10.0)..(hi * 10.0);
    }
    (lo / 2.0)..(hi * 2.0)
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
    let fmt = format_of(path)?;
    let size = (1200, 900);
    match fmt {
        Format::Svg => {
            ensure_font()?;
            let root = SVGBackend::new(path, size).into_drawing_area();
            draw_figure1(&root, fig).map_err(|e| fail(path, e))?;
            root.present().map_err(|e| fail(path, e))
        }
        Format::Png => {
            ensure_font()?;
            let root = BitMapBackend::new(path, size).into_drawing_area();
            draw_figure1(&root, fig).map_err(|e| fail(path, e))?;
            root.present().map_err(|e| fail(path, e))
        }
    }
}

fn draw_figure1<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure1) -> DrawResult {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(&fig.title, ("sans-serif", 24)).map_err(e)?;
    let (top, bottom) = root.split_vertically(root.dim_in_pixel().1 / 2);
    let (tl, tr) = top.split_horizontally(top.dim_in_pixel().0 / 2);

    // Top left: y(t) with the events as red dashed lines.
    let t_range = span(fig.trajectory.iter().map(|p| p.0));
    let y_range = span(fig.trajectory.iter().map(|p| p.1));
    {
        let mut chart = ChartBuilder::on(&tl)
            .caption(
                format!("{}(t) and events", fig.observable),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(t_range.clone(), y_range.clone())
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("t")
            .y_desc(fig.observable.as_str())
            .draw()
            .map_err(e)?;
        chart
            .draw_series(LineSeries::new(
                fig.trajectory.iter().copied(),
                BLUE.stroke_width(2),
            ))
            .map_err(e)?;
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
        let mut chart = ChartBuilder::on(&tr)
            .caption(
                format!("d{}/d{}: density and atoms", fig.observable, fig.param),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(t_range.clone(), d_range)
            .map_err(e)?;
        chart.configure_mesh().x_desc("t").draw().map_err(e)?;
        chart
            .draw_series(LineSeries::new(
                fig.density.iter().copied(),
                BLUE.stroke_width(2),
            ))
            .map_err(e)?
            .label("density")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE));
        for &(tk, a) in &fig.atoms {
            chart
                .draw_series(LineSeries::new([(tk, 0.0), (tk, a)], RED.stroke_width(2)))
                .map_err(e)?;
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
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
    }

    // Bottom: d/dθ ∫₀ᵗ y ds, MV-AD against FD.
    {
        let c_range = span(
            fig.cumulative_mvad
                .iter()
                .chain(&fig.cumulative_fd)
                .map(|p| p.1),
        );
        let mut chart = ChartBuilder::on(&bottom)
            .caption(
                format!(
                    "d/d{} of the integral of {} up to t: MV-AD vs central FD   {}",
                    fig.param, fig.observable, fig.note
                ),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(t_range, c_range)
            .map_err(e)?;
        chart.configure_mesh().x_desc("t").draw().map_err(e)?;
        chart
            .draw_series(LineSeries::new(
                fig.cumulative_mvad.iter().copied(),
                BLUE.stroke_width(3),
            ))
            .map_err(e)?
            .label("MV-AD")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE.stroke_width(3)));
        chart
            .draw_series(DashedLineSeries::new(
                fig.cumulative_fd.iter().copied(),
                8,
                5,
                RED.stroke_width(2),
            ))
            .map_err(e)?
            .label("central FD")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

/// One curve of a work-precision picture: (wall seconds, error) points.
#[derive(Clone, Debug, Default)]
pub struct Curve {
    /// Legend text.
    pub label: String,
    /// (wall seconds, error) points; non-positive errors are drawn at the floor.
    pub points: Vec<(f64, f64)>,
}

/// Draws work-precision panels (one per quantity, side by side) log-log into `path`.
pub fn workprec(path: &Path, title: &str, panels: &[(String, Vec<Curve>)]) -> Result<(), CliError> {
    let fmt = format_of(path)?;
    let size = (600 * panels.len().max(1) as u32, 500);
    match fmt {
        Format::Svg => {
            ensure_font()?;
            let root = SVGBackend::new(path, size).into_drawing_area();
            draw_workprec(&root, title, panels).map_err(|e| fail(path, e))?;
            root.present().map_err(|e| fail(path, e))
        }
        Format::Png => {
            ensure_font()?;
            let root = BitMapBackend::new(path, size).into_drawing_area();
            draw_workprec(&root, title, panels).map_err(|e| fail(path, e))?;
            root.present().map_err(|e| fail(path, e))
        }
    }
}

fn draw_workprec<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    panels: &[(String, Vec<Curve>)],
) -> DrawResult {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(e)?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    const FLOOR: f64 = 1e-17;
    let colors = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    for ((name, curves), area) in panels.iter().zip(areas.iter()) {
        let xr = log_span(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
        let yr = log_span(
            curves
                .iter()
                .flat_map(|c| c.points.iter().map(|p| p.1.max(FLOOR))),
        );
        let mut chart = ChartBuilder::on(area)
            .caption(name.as_str(), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(xr.log_scale(), yr.log_scale())
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("wall time (s)")
            .y_desc("error")
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(e)?;
        for (i, c) in curves.iter().enumerate() {
            let color = colors[i % colors.len()];
            let pts: Vec<(f64, f64)> = c
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.0 > 0.0 && p.1.is_finite())
                .map(|&(x, y)| (x, y.max(FLOOR)))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))
                .map_err(e)?
                .label(c.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                .map_err(e)?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
    }
    Ok(())
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

    fn tmp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("mvad-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir.join(name)
    }

    #[test]
    fn figure1_svg_and_png() {
        let fig = sample_figure();
        let svg = tmp("fig.svg");
        figure1(&svg, &fig).expect("svg");
        let text = std::fs::read_to_string(&svg).expect("written");
        assert!(text.starts_with("<svg"), "{}", &text[..50.min(text.len())]);
        assert!(text.contains("density and atoms"));
        let png = tmp("fig.png");
        figure1(&png, &fig).expect("png");
        let bytes = std::fs::read(&png).expect("written");
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }

    #[test]
    fn workprec_svg_and_png() {
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
        workprec(&tmp("wp.svg"), "wp", &panels).expect("svg");
        workprec(&tmp("wp.png"), "wp", &panels).expect("png");
    }

    #[test]
    fn bad_paths_are_errors_not_panics() {
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
        figure1(&tmp("empty.svg"), &empty).expect("empty figure draws");
    }

    #[test]
    fn spans_are_finite_and_nonempty() {
        let r = span([1.0, f64::NAN, 1.0]);
        assert!(r.start < r.end && r.start.is_finite());
        let r = span([]);
        assert!(r.start < r.end);
        let r = log_span([0.0, -1.0, 1e-3]);
        assert!(r.start > 0.0 && r.start < r.end);
    }
}
