//! Figures, PNG or SVG by file extension: runs in the style of the paper's figure 4 (each
//! monitored event's confidence against time, with the true onset and the confirmations
//! marked), and the features' distributions in and outside labelled events.

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

/// A figure that can be drawn on any backend.
trait Figure {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>;
}

/// Draws `figure` at `size` pixels and writes it to `path`, PNG or SVG by its extension.
fn write_figure(path: &Path, size: (u32, u32), figure: &impl Figure) -> Result<(), PlotError> {
    fonts();
    let shown = path.display().to_string();
    let drawn = match path.extension().and_then(|e| e.to_str()) {
        Some("png") => {
            let root = BitMapBackend::new(path, size).into_drawing_area();
            figure
                .draw(&root)
                .and_then(|()| root.present())
                .map_err(bitmap_message)
        }
        Some("svg") => {
            let root = SVGBackend::new(path, size).into_drawing_area();
            figure
                .draw(&root)
                .and_then(|()| root.present())
                .map_err(|e| e.to_string())
        }
        _ => return Err(PlotError::Format(shown)),
    };
    drawn.map_err(|message| PlotError::Draw {
        path: shown,
        message,
    })
}

/// One panel of a grid figure.
trait Panel {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>;
}

/// Panels in a grid, `columns` wide, row by row.
struct Grid<'p, P> {
    panels: &'p [P],
    columns: usize,
}

impl<P: Panel> Grid<'_, P> {
    fn rows(&self) -> usize {
        self.panels.len().div_ceil(self.columns).max(1)
    }
}

impl<P: Panel> Figure for Grid<'_, P> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        for (area, panel) in root
            .split_evenly((self.rows(), self.columns))
            .iter()
            .zip(self.panels)
        {
            panel.draw_panel(area)?;
        }
        Ok(())
    }
}

impl Panel for RunPlot<'_> {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        draw_run(area, self)
    }
}

impl Panel for FeaturePanel<'_> {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        draw_feature(area, self)
    }
}

/// Writes a grid of runs (`columns` wide) to `path`, each panel `panel` pixels.
pub fn write_grid(
    path: &Path,
    runs: &[RunPlot<'_>],
    columns: usize,
    panel: (u32, u32),
) -> Result<(), PlotError> {
    let grid = Grid {
        panels: runs,
        columns: columns.clamp(1, runs.len().max(1)),
    };
    let size = (panel.0 * grid.columns as u32, panel.1 * grid.rows() as u32);
    write_figure(path, size, &grid)
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

/// One feature's distributions for the features figure.
#[derive(Clone, Debug)]
pub struct FeaturePanel<'a> {
    /// The feature's name.
    pub feature: &'a str,
    /// Values outside events.
    pub outside: &'a [f64],
    /// Each event's name, its values and the best single threshold's balanced accuracy.
    pub events: Vec<(&'a str, &'a [f64], f64)>,
}

/// Bins per histogram.
const BINS: usize = 60;
/// The lowest density drawn, relative to the highest: the log scale shows the tails, where
/// events and the time outside them part, down to this.
const FLOOR: f64 = 1e-5;

/// Writes one panel per feature to `path`: the histogram (as a density, on a log scale) of
/// its values outside events in grey and inside each event in the event's colour, each event's
/// separability in the legend.
pub fn write_features(path: &Path, panels: &[FeaturePanel<'_>]) -> Result<(), PlotError> {
    let grid = Grid {
        panels,
        columns: panels.len().clamp(1, 3),
    };
    let size = (460 * grid.columns as u32, 300 * grid.rows() as u32);
    write_figure(path, size, &grid)
}

/// The value at quantile `q` of sorted values.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let k = ((q * sorted.len() as f64) as usize).min(sorted.len().saturating_sub(1));
    sorted.get(k).copied().unwrap_or(0.0)
}

fn draw_feature<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &FeaturePanel<'_>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    // The range holding all but the extreme 0.5 % of every set.
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let sets: Vec<(&str, &[f64], RGBColor)> =
        std::iter::once(("outside", panel.outside, RGBColor(120, 120, 120)))
            .chain(
                panel
                    .events
                    .iter()
                    .enumerate()
                    .map(|(k, (name, values, _))| (*name, *values, COLORS[k % COLORS.len()])),
            )
            .collect();
    let sorted: Vec<Vec<f64>> = sets
        .iter()
        .map(|(_, v, _)| {
            let mut s = v.to_vec();
            s.sort_by(f64::total_cmp);
            s
        })
        .collect();
    for s in sorted.iter().filter(|s| !s.is_empty()) {
        lo = lo.min(quantile(s, 0.005));
        hi = hi.max(quantile(s, 0.995));
    }
    if !(lo.is_finite() && hi.is_finite()) {
        (lo, hi) = (0.0, 1.0);
    }
    if hi <= lo {
        (lo, hi) = (lo - 0.5, hi + 0.5);
    }
    let width = (hi - lo) / BINS as f64;
    let density = |s: &[f64]| -> Vec<f64> {
        let mut counts = vec![0.0; BINS];
        for v in s {
            let b = ((v - lo) / width).floor();
            if (0.0..BINS as f64).contains(&b) {
                counts[b as usize] += 1.0;
            }
        }
        let total = (s.len() as f64 * width).max(f64::MIN_POSITIVE);
        counts.iter().map(|c| c / total).collect()
    };
    let histograms: Vec<Vec<f64>> = sorted.iter().map(|s| density(s)).collect();
    let top = histograms
        .iter()
        .flatten()
        .copied()
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE)
        * 1.1;
    let mut chart = ChartBuilder::on(area)
        .caption(
            panel.feature,
            ("sans-serif", 16).into_font().style(FontStyle::Bold),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(lo..hi, (top * FLOOR..top).log_scale())?;
    chart
        .configure_mesh()
        .x_labels(6)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .y_desc("density (log)")
        .light_line_style(RGBColor(235, 235, 235))
        .label_style(("sans-serif", 12))
        .draw()?;
    for (k, ((name, values, color), h)) in sets.iter().zip(&histograms).enumerate() {
        if values.is_empty() {
            continue;
        }
        // The outline of the histogram, as steps.
        let steps = h.iter().enumerate().flat_map(|(b, d)| {
            let (x, d) = (lo + b as f64 * width, d.max(top * FLOOR));
            [(x, d), (x + width, d)]
        });
        let label = match k.checked_sub(1).and_then(|e| panel.events.get(e)) {
            Some((_, _, accuracy)) => {
                format!("{name}: one threshold {:.0} %", accuracy * 100.0)
            }
            None => name.to_string(),
        };
        let color = *color;
        chart
            .draw_series(LineSeries::new(steps, color.stroke_width(2)))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .label_font(("sans-serif", 12))
        .draw()?;
    Ok(())
}

/// One scenario's runs for the figure of `evaluate --plot-bins`: each run's value of the
/// parameter its scenario is binned by against its peak confidence, by outcome.
#[derive(Clone, Debug)]
pub struct BinPanel {
    /// The scenario.
    pub title: String,
    /// The parameter and its unit.
    pub x_label: String,
    /// What the confidence is of.
    pub y_label: String,
    /// A log scale for the parameter (it spans decades).
    pub log_x: bool,
    /// `(parameter, peak confidence in [0, 1])` of the runs that went right, confirmed a
    /// wrong event, missed, and confirmed more than once, in that order.
    pub points: [Vec<(f64, f64)>; 4],
}

/// The outcomes of [`BinPanel::points`], with their colours.
const OUTCOMES: [(&str, RGBColor); 4] = [
    ("right", RGBColor(0, 158, 115)),
    ("wrong", RGBColor(213, 94, 0)),
    ("missed", RGBColor(0, 114, 178)),
    ("repeated", RGBColor(204, 121, 167)),
];

/// Writes one panel per scenario to `path`: each run's peak confidence against the
/// parameter that matters most for it, a dot per run coloured by outcome.
pub fn write_bins(path: &Path, panels: &[BinPanel]) -> Result<(), PlotError> {
    let grid = Grid {
        panels,
        columns: panels.len().clamp(1, 3),
    };
    let size = (460 * grid.columns as u32, 300 * grid.rows() as u32);
    write_figure(path, size, &grid)
}

impl Panel for BinPanel {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let xs = self.points.iter().flatten().map(|p| p.0);
        let (mut lo, mut hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
        if !(lo.is_finite() && hi.is_finite()) || (self.log_x && lo <= 0.0) {
            (lo, hi) = (1.0, 10.0);
        }
        // Some room on either side, so that the outermost runs show whole.
        let (lo, hi) = if self.log_x {
            (lo / 1.1, hi * 1.1)
        } else {
            let pad = ((hi - lo) * 0.05).max(1e-9 * hi.abs().max(1.0));
            (lo - pad, hi + pad)
        };
        let caption = (
            self.title.as_str(),
            ("sans-serif", 16).into_font().style(FontStyle::Bold),
        );
        if self.log_x {
            let mut chart = ChartBuilder::on(area)
                .caption(caption.0, caption.1)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(45)
                .build_cartesian_2d((lo..hi).log_scale(), -0.02..1.02)?;
            chart
                .configure_mesh()
                .x_labels(5)
                .x_label_formatter(&|v| format!("{v:.2e}"))
                .x_desc(self.x_label.as_str())
                .y_desc(self.y_label.as_str())
                .light_line_style(RGBColor(235, 235, 235))
                .label_style(("sans-serif", 12))
                .draw()?;
            draw_outcomes(&mut chart, &self.points)
        } else {
            let mut chart = ChartBuilder::on(area)
                .caption(caption.0, caption.1)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(45)
                .build_cartesian_2d(lo..hi, -0.02..1.02)?;
            chart
                .configure_mesh()
                .x_labels(5)
                .x_desc(self.x_label.as_str())
                .y_desc(self.y_label.as_str())
                .light_line_style(RGBColor(235, 235, 235))
                .label_style(("sans-serif", 12))
                .draw()?;
            draw_outcomes(&mut chart, &self.points)
        }
    }
}

/// A dot per run, coloured by outcome, with a legend of the outcomes that occur.
fn draw_outcomes<'a, DB, X>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, plotters::coord::types::RangedCoordf64>>,
    points: &[Vec<(f64, f64)>; 4],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    X: plotters::coord::ranged1d::Ranged<ValueType = f64>,
{
    for ((name, color), runs) in OUTCOMES.iter().zip(points) {
        if runs.is_empty() {
            continue;
        }
        let color = *color;
        chart
            .draw_series(
                runs.iter()
                    .map(move |&p| Circle::new(p, 2, color.mix(0.6).filled())),
            )?
            .label(format!("{name} ({})", runs.len()))
            .legend(move |(x, y)| Circle::new((x + 6, y), 3, color.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .label_font(("sans-serif", 12))
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
