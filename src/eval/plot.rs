//! The PNG `bench localize --plot` writes: the antennas' paths, the tags' true positions and
//! the estimates (true and estimated poses), top view.

use std::path::Path;

use plotters::prelude::*;

use super::bench::{Run, Scores};

/// TrueType fonts tried for the labels (Debian's DejaVu, pulled in with fontconfig).
const FONTS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Registers a system font for the labels; `false` when none is there (the plot then has
/// no text).
pub(super) fn font() -> bool {
    static FOUND: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *FOUND.get_or_init(|| {
        FONTS.iter().any(|p| match std::fs::read(p) {
            // Registered once for the process's life.
            Ok(bytes) => plotters::style::register_font(
                "sans-serif",
                FontStyle::Normal,
                Box::leak(bytes.into_boxed_slice()),
            )
            .is_ok(),
            Err(_) => false,
        })
    })
}

/// The chart `plot` draws on: metres on both axes of a bitmap.
type Chart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    plotters::coord::cartesian::Cartesian2d<
        plotters::coord::types::RangedCoordf64,
        plotters::coord::types::RangedCoordf64,
    >,
>;

/// Draws `run`'s truth and the estimates of `with_true` and `with_estimated` to `path`.
pub fn plot(
    path: &Path,
    title: &str,
    run: &Run,
    with_true: &Scores,
    with_estimated: &Scores,
) -> Result<(), String> {
    let text = font();
    let mut xs: Vec<f64> = run.truth.iter().map(|t| t.1[0]).collect();
    let mut ys: Vec<f64> = run.truth.iter().map(|t| t.1[1]).collect();
    let path_points: Vec<(f64, f64)> = run
        .true_poses
        .samples()
        .iter()
        .map(|p| (p.pose.position[0], p.pose.position[1]))
        .collect();
    xs.extend(path_points.iter().map(|p| p.0));
    ys.extend(path_points.iter().map(|p| p.1));
    let (x0, x1) = bounds(&xs);
    let (y0, y1) = bounds(&ys);
    let root = BitMapBackend::new(path, (1200, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20);
    if text {
        builder
            .caption(title, ("sans-serif", 22))
            .x_label_area_size(40)
            .y_label_area_size(50);
    }
    let mut chart = builder
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("x (m)").y_desc("y (m)");
    } else {
        mesh.disable_x_axis().disable_y_axis();
    }
    mesh.draw().map_err(|e| e.to_string())?;
    draw_truth(&mut chart, run, &path_points, text)?;
    for (scores, color) in [(with_true, BLUE), (with_estimated, RED)] {
        draw_estimates(&mut chart, scores, color, text)?;
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

/// Draws the antenna path and the tags' true positions (with legend entries if `text`).
fn draw_truth(
    chart: &mut Chart<'_, '_>,
    run: &Run,
    path_points: &[(f64, f64)],
    text: bool,
) -> Result<(), String> {
    let grey = RGBColor(150, 150, 150);
    let series = chart
        .draw_series(LineSeries::new(path_points.iter().copied(), &grey))
        .map_err(|e| e.to_string())?;
    if text {
        series
            .label("antenna path")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));
    }
    let series = chart
        .draw_series(
            run.truth
                .iter()
                .map(|t| Cross::new((t.1[0], t.1[1]), 7, BLACK.stroke_width(2))),
        )
        .map_err(|e| e.to_string())?;
    if text {
        series
            .label("truth")
            .legend(|(x, y)| Cross::new((x + 10, y), 6, BLACK.stroke_width(2)));
    }
    Ok(())
}

/// Draws the estimates of `scores` in `color`, with a legend entry if `text`.
fn draw_estimates(
    chart: &mut Chart<'_, '_>,
    scores: &Scores,
    color: RGBColor,
    text: bool,
) -> Result<(), String> {
    let points: Vec<(f64, f64)> = scores
        .estimates
        .iter()
        .filter_map(|e| e.estimate.map(|p| (p[0], p[1])))
        .collect();
    let series = chart
        .draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))
        .map_err(|e| e.to_string())?;
    if text {
        series
            .label(format!(
                "{}, {} poses: mean {:.1} mm",
                scores.estimator,
                scores.poses,
                scores.mean * 1e3
            ))
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
    }
    Ok(())
}

/// The range of `v` with a margin, at least 1 m wide.
fn bounds(v: &[f64]) -> (f64, f64) {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let margin = ((hi - lo) * 0.08).max(0.5);
    (lo - margin, hi + margin)
}
