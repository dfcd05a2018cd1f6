//! Plots of a run, as SVG: the map of the paper's Figure 9 (survey areas blue, forbidden zones
//! red, planned trace yellow, simulated vehicle trace green, events marked where they
//! happened) and a depth/time plot. Drawn with plotters' SVG backend.
//!
//! A [`Trace`] is plain data (timestamped positions and depths, events with positions, the
//! planned polylines), so a trace recorded by a real vehicle plots the same way.

use std::fmt;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::geom::Position;
use crate::mission::{EndArea, Mission};

/// Colour of the survey areas.
pub const SURVEY_AREA: RGBColor = RGBColor(0, 0, 255);
/// Colour of the forbidden zones.
pub const FORBIDDEN: RGBColor = RGBColor(255, 0, 0);
/// Colour of the planned trace.
pub const PLANNED: RGBColor = RGBColor(255, 255, 0);
/// Colour of the vehicle's trace.
pub const VEHICLE: RGBColor = RGBColor(0, 160, 0);
/// Colour of the end area and the start point.
pub const END_AREA: RGBColor = RGBColor(128, 0, 128);
/// Colour of the event marks (white on the sea).
pub const EVENT: RGBColor = RGBColor(255, 255, 255);
/// The sea: a dark background, as on an operator's console, so that yellow shows.
pub const SEA: RGBColor = RGBColor(30, 50, 80);

/// A recorded position of the vehicle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracePoint {
    /// Time (s).
    pub time: f64,
    /// Position.
    pub position: Position,
    /// Depth (m).
    pub depth: f64,
    /// Index of the area whose survey line is being flown, if any (the sonar records).
    pub surveying: Option<usize>,
}

/// Something that happened, where it happened.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceEvent {
    /// Time (s).
    pub time: f64,
    /// Where the vehicle was.
    pub position: Position,
    /// What happened.
    pub label: String,
}

/// A run's record.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// The vehicle's positions, in time order.
    pub points: Vec<TracePoint>,
    /// The events, in time order.
    pub events: Vec<TraceEvent>,
    /// The planned polylines: the plan, then each replan.
    pub planned: Vec<Vec<Position>>,
}

/// A plot that could not be drawn or written.
#[derive(Debug)]
pub enum PlotError {
    /// Plotters failed to draw.
    Draw(String),
    /// The file could not be written.
    Io(std::io::Error),
}

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlotError::Draw(message) => write!(f, "cannot draw the plot: {message}"),
            PlotError::Io(e) => write!(f, "cannot write the plot: {e}"),
        }
    }
}

impl std::error::Error for PlotError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            PlotError::Io(e) => Some(e),
            PlotError::Draw(_) => None,
        }
    }
}

fn draw_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> PlotError {
    PlotError::Draw(e.to_string())
}

/// At most this many points of a trace are drawn: a long run's 10 Hz record would make a
/// needlessly heavy SVG.
const MAX_DRAWN_POINTS: usize = 4000;

fn thin<T: Copy>(items: &[T]) -> Vec<T> {
    if items.is_empty() {
        return Vec::new();
    }
    let stride = items.len().div_ceil(MAX_DRAWN_POINTS).max(1);
    let mut out: Vec<T> = items.iter().step_by(stride).copied().collect();
    if let (Some(&last), true) = (items.last(), !(items.len() - 1).is_multiple_of(stride)) {
        out.push(last);
    }
    out
}

/// The map of the run as SVG text (`size` in pixels).
pub fn map_svg(mission: &Mission, trace: &Trace, size: (u32, u32)) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_map(&root, mission, trace)?;
        root.present().map_err(draw_err)?;
    }
    Ok(svg)
}

/// The depth/time plot of the run as SVG text.
pub fn depth_svg(trace: &Trace, size: (u32, u32)) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_depth(&root, trace)?;
        root.present().map_err(draw_err)?;
    }
    Ok(svg)
}

/// Writes [`map_svg`] to `path` (1000 × 800 pixels).
pub fn write_map(path: &Path, mission: &Mission, trace: &Trace) -> Result<(), PlotError> {
    let svg = map_svg(mission, trace, (1000, 800))?;
    std::fs::write(path, svg).map_err(PlotError::Io)
}

/// Writes [`depth_svg`] to `path` (1000 × 400 pixels).
pub fn write_depth(path: &Path, trace: &Trace) -> Result<(), PlotError> {
    let svg = depth_svg(trace, (1000, 400))?;
    std::fs::write(path, svg).map_err(PlotError::Io)
}

fn xy(p: &Position) -> (f64, f64) {
    (p.x, p.y)
}

fn ring(polygon: &geo::Polygon<f64>) -> Vec<(f64, f64)> {
    polygon.exterior().0.iter().map(xy).collect()
}

fn draw_map<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    mission: &Mission,
    trace: &Trace,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(draw_err)?;
    // Everything drawn decides the extent; the extent is widened so that a metre is as long
    // east as north.
    let mut points: Vec<Position> = vec![mission.start];
    points.extend(
        mission
            .areas
            .iter()
            .flat_map(|a| a.polygon.exterior().0.clone()),
    );
    points.extend(
        mission
            .forbidden
            .iter()
            .flat_map(|z| z.polygon.exterior().0.clone()),
    );
    match &mission.end {
        EndArea::Polygon(p) => points.extend(p.exterior().0.iter().copied()),
        EndArea::Point { at, radius } => {
            points.push(
                *at + Position {
                    x: *radius,
                    y: *radius,
                },
            );
            points.push(
                *at - Position {
                    x: *radius,
                    y: *radius,
                },
            );
        }
    }
    points.extend(trace.points.iter().map(|p| p.position));
    points.extend(trace.planned.iter().flatten().copied());
    points.extend(trace.events.iter().map(|e| e.position));
    let points: Vec<Position> = points
        .into_iter()
        .filter(|p| p.x.is_finite() && p.y.is_finite())
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = points.iter().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), p| (a.min(p.x), b.max(p.x), c.min(p.y), d.max(p.y)),
    );
    if !(x0.is_finite() && y0.is_finite()) {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(10.0);
    let (mut x0, mut x1, mut y0, mut y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);
    let (w, h) = root.dim_in_pixel();
    let (plot_w, plot_h) = (
        f64::from(w.saturating_sub(80)).max(1.0),
        f64::from(h.saturating_sub(80)).max(1.0),
    );
    let scale = ((x1 - x0) / plot_w).max((y1 - y0) / plot_h);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    (x0, x1) = (cx - scale * plot_w / 2.0, cx + scale * plot_w / 2.0);
    (y0, y1) = (cy - scale * plot_h / 2.0, cy + scale * plot_h / 2.0);

    let mut chart = ChartBuilder::on(root)
        .caption(format!("Mission {}", mission.name), ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x east (m)")
        .y_desc("y north (m)")
        .draw()
        .map_err(draw_err)?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(x0, y0), (x1, y1)],
            SEA.filled(),
        )))
        .map_err(draw_err)?;

    for area in &mission.areas {
        let r = ring(&area.polygon);
        chart
            .draw_series(std::iter::once(Polygon::new(
                r.clone(),
                SURVEY_AREA.mix(0.35).filled(),
            )))
            .map_err(draw_err)?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                r,
                SURVEY_AREA.stroke_width(2),
            )))
            .map_err(draw_err)?
            .label(format!("survey area {}", area.name))
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 15, y + 5)], SURVEY_AREA.filled()));
    }
    for zone in &mission.forbidden {
        let r = ring(&zone.polygon);
        chart
            .draw_series(std::iter::once(Polygon::new(
                r.clone(),
                FORBIDDEN.mix(0.5).filled(),
            )))
            .map_err(draw_err)?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                r,
                FORBIDDEN.stroke_width(2),
            )))
            .map_err(draw_err)?;
    }
    match &mission.end {
        EndArea::Polygon(p) => {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    ring(p),
                    END_AREA.stroke_width(2),
                )))
                .map_err(draw_err)?;
        }
        EndArea::Point { at, radius } => {
            let circle: Vec<(f64, f64)> = (0..=48)
                .map(|k| {
                    let a = std::f64::consts::TAU * f64::from(k) / 48.0;
                    (at.x + radius * a.cos(), at.y + radius * a.sin())
                })
                .collect();
            chart
                .draw_series(std::iter::once(PathElement::new(
                    circle,
                    END_AREA.stroke_width(2),
                )))
                .map_err(draw_err)?;
        }
    }
    chart
        .draw_series(std::iter::once(TriangleMarker::new(
            xy(&mission.start),
            8,
            END_AREA.filled(),
        )))
        .map_err(draw_err)?;

    for polyline in &trace.planned {
        chart
            .draw_series(std::iter::once(PathElement::new(
                polyline.iter().map(xy).collect::<Vec<_>>(),
                PLANNED.stroke_width(2),
            )))
            .map_err(draw_err)?;
    }
    let track: Vec<(f64, f64)> = thin(&trace.points)
        .iter()
        .map(|p| xy(&p.position))
        .collect();
    chart
        .draw_series(std::iter::once(PathElement::new(
            track,
            VEHICLE.stroke_width(2),
        )))
        .map_err(draw_err)?;
    let mut marked: Vec<Position> = Vec::new();
    for event in &trace.events {
        if !(event.position.x.is_finite() && event.position.y.is_finite()) {
            continue;
        }
        // Events at one place (a fault and its alarm) get their labels stacked, not overlaid.
        let stacked = marked
            .iter()
            .filter(|&&p| crate::geom::distance(p, event.position) < 15.0 * scale)
            .count();
        marked.push(event.position);
        let dy = -12 - 14 * i32::try_from(stacked).unwrap_or(i32::MAX / 28);
        let at = xy(&event.position);
        chart
            .draw_series(std::iter::once(
                EmptyElement::at(at)
                    + Cross::new((0, 0), 5, EVENT.stroke_width(2))
                    + Text::new(
                        event.label.clone(),
                        (7, dy),
                        ("sans-serif", 12).into_font().color(&EVENT),
                    ),
            ))
            .map_err(draw_err)?;
    }
    Ok(())
}

fn draw_depth<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    trace: &Trace,
) -> Result<(), PlotError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(draw_err)?;
    let points = thin(&trace.points);
    let t1 = points
        .iter()
        .map(|p| p.time)
        .filter(|t| t.is_finite())
        .fold(1.0, f64::max);
    let deepest = points
        .iter()
        .map(|p| p.depth)
        .filter(|d| d.is_finite())
        .fold(1.0, f64::max);
    // Depth grows downwards: the chart's y is minus the depth, labelled as depth.
    let mut chart = ChartBuilder::on(root)
        .caption("Depth", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t1, -(deepest * 1.1)..0.5)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("depth (m)")
        .y_label_formatter(&|v| format!("{:.0}", 0.0 - v))
        .draw()
        .map_err(draw_err)?;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|p| (p.time, -p.depth)),
            VEHICLE.stroke_width(2),
        ))
        .map_err(draw_err)?;
    for event in trace.events.iter().filter(|e| e.time.is_finite()) {
        let i = trace.points.partition_point(|p| p.time < event.time);
        let depth = trace
            .points
            .get(i.min(trace.points.len().saturating_sub(1)))
            .map_or(0.0, |p| p.depth);
        chart
            .draw_series(std::iter::once(
                EmptyElement::at((event.time, -depth))
                    + Cross::new((0, 0), 5, BLACK.stroke_width(2))
                    + Text::new(event.label.clone(), (7, 5), ("sans-serif", 12).into_font()),
            ))
            .map_err(draw_err)?;
    }
    Ok(())
}
