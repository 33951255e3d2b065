//! Figures in the style of the paper's figure 4: each monitored event's confidence against
//! time, with the true onset and the confirmations marked. PNG or SVG by file extension.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::replay::DecisionRecord;

/// One run to draw.
#[derive(Clone, Debug)]
pub struct RunPlot<'a> {
    /// Title above the chart.
    pub title: String,
    /// Time of each tick (s).
    pub t: &'a [f64],
    /// Each event's name and confidence per tick.
    pub series: Vec<(String, Vec<f64>)>,
    /// The true event and its onset (s), if known.
    pub truth: Option<(String, f64)>,
    /// Levels raised.
    pub decisions: &'a [DecisionRecord],
}

/// Why a figure could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The file name ends in neither `.png` nor `.svg`.
    #[error("{0}: plots are written as .png or .svg")]
    Format(String),
    /// Drawing or writing failed.
    #[error("{path}: {message}")]
    Draw {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
}

const COLORS: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
];

fn fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is compiled in, so registration cannot fail for want of a file.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
        let _ = plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
    });
}

/// Writes a grid of runs (`columns` wide) to `path`, each panel `panel` pixels.
pub fn write_grid(
    path: &Path,
    runs: &[RunPlot<'_>],
    columns: usize,
    panel: (u32, u32),
) -> Result<(), PlotError> {
    fonts();
    let columns = columns.clamp(1, runs.len().max(1));
    let rows = runs.len().div_ceil(columns).max(1);
    let size = (panel.0 * columns as u32, panel.1 * rows as u32);
    let shown = path.display().to_string();
    let drawn = match path.extension().and_then(|e| e.to_str()) {
        Some("png") => draw_grid(
            &BitMapBackend::new(path, size).into_drawing_area(),
            runs,
            rows,
            columns,
        )
        .map_err(bitmap_message),
        Some("svg") => draw_grid(
            &SVGBackend::new(path, size).into_drawing_area(),
            runs,
            rows,
            columns,
        )
        .map_err(|e| e.to_string()),
        _ => return Err(PlotError::Format(shown)),
    };
    drawn.map_err(|message| PlotError::Draw {
        path: shown,
        message,
    })
}

/// What went wrong writing a PNG, as a person reads it (the backend's own text is its
/// debug form).
fn bitmap_message(e: DrawingAreaErrorKind<plotters_bitmap::BitMapBackendError>) -> String {
    use plotters_bitmap::BitMapBackendError as B;
    match e {
        DrawingAreaErrorKind::BackendError(plotters_backend::DrawingErrorKind::DrawingError(b)) => {
            match b {
                B::IOError(io) => io.to_string(),
                B::ImageError(image) => image.to_string(),
                B::InvalidBuffer => "the image buffer has the wrong size".to_string(),
            }
        }
        other => other.to_string(),
    }
}

/// Writes one run to `path`.
pub fn write_run(path: &Path, run: &RunPlot<'_>) -> Result<(), PlotError> {
    write_grid(path, std::slice::from_ref(run), 1, (900, 420))
}

/// Draws every run into its panel of `root` and writes the file.
fn draw_grid<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    runs: &[RunPlot<'_>],
    rows: usize,
    columns: usize,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    root.fill(&WHITE)?;
    for (area, run) in root.split_evenly((rows, columns)).iter().zip(runs) {
        draw_run(area, run)?;
    }
    root.present()
}

fn draw_run<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    run: &RunPlot<'_>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let ms = |s: f64| s * 1e3;
    let t0 = run.t.first().copied().unwrap_or(0.0);
    let t1 = run.t.last().copied().unwrap_or(1.0).max(t0 + 1e-3);
    let mut chart = ChartBuilder::on(area)
        .caption(
            &run.title,
            ("sans-serif", 18).into_font().style(FontStyle::Bold),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(ms(t0)..ms(t1), -0.02f64..1.05f64)?;
    chart
        .configure_mesh()
        .x_desc("time [ms]")
        .y_desc("confidence")
        .light_line_style(RGBColor(235, 235, 235))
        .label_style(("sans-serif", 13))
        .draw()?;

    if let Some((event, onset)) = &run.truth {
        let style = ShapeStyle::from(&BLACK.mix(0.7)).stroke_width(1);
        chart
            .draw_series(DashedLineSeries::new(
                vec![(ms(*onset), 0.0), (ms(*onset), 1.05)],
                6,
                4,
                style,
            ))?
            .label(format!("true {event} onset"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
    }
    // Thin the series to about two points per pixel column; spikes survive as the max.
    let stride = (run.t.len() / 2000).max(1);
    for (k, (name, values)) in run.series.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let points = run
            .t
            .chunks(stride)
            .zip(values.chunks(stride))
            .map(|(t, v)| (ms(t[0]), v.iter().copied().fold(0.0, f64::max)));
        chart
            .draw_series(LineSeries::new(points, color.stroke_width(2)))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        for d in run.decisions.iter().filter(|d| &d.event == name) {
            let marker_at = (ms(d.t_s), d.confidence);
            if d.is_confirm() {
                chart.draw_series(std::iter::once(Circle::new(marker_at, 6, color.filled())))?;
                chart.draw_series(std::iter::once(Text::new(
                    format!("{} confirmed {:.1} ms", name, ms(d.t_s)),
                    (
                        ms(d.t_s) + 0.01 * (ms(t1) - ms(t0)),
                        (d.confidence - 0.08).max(0.05),
                    ),
                    ("sans-serif", 13).into_font().color(&color),
                )))?;
            } else {
                chart.draw_series(std::iter::once(TriangleMarker::new(
                    marker_at,
                    6,
                    color.filled(),
                )))?;
            }
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .label_font(("sans-serif", 13))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod message_tests {
    use super::*;

    /// A PNG that cannot be written says why in words, not as the backend's debug form.
    #[test]
    fn png_write_errors_read_as_words() {
        let io = std::io::Error::new(std::io::ErrorKind::StorageFull, "no space left on device");
        let e =
            DrawingAreaErrorKind::BackendError(plotters_backend::DrawingErrorKind::DrawingError(
                plotters_bitmap::BitMapBackendError::IOError(io),
            ));
        let m = bitmap_message(e);
        assert_eq!(m, "no space left on device");
        assert!(!m.contains("IOError") && !m.contains("Os {"));
    }
}
