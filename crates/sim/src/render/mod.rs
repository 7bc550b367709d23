//! Pictures of a map with robots, goals, planned waypoints and executed
//! trajectories, as PNG or SVG (chosen by the file extension).
//!
//! Ground maps are drawn from above. The Drone's world gets a top view (x, y) above
//! a side view (x, z) at the same scale, each with its axes in metres, under a legend:
//! walls are grey, the duck yellow, goals green discs of their radius (regions to
//! avoid red), planned
//! waypoints blue dots joined by thin lines (another planner's purple), executed trajectories orange, the robot a
//! black circle with a line showing its heading. Charts (training curves, result bars)
//! are in [`save_chart`] and [`save_bars`]; text uses an embedded font (`style`).
//!
//! Files are written atomically (to a temporary name, then renamed) and an existing
//! file is never replaced unless `overwrite` is set.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::map::Map;

mod chart;
mod style;

pub use chart::{BarChart, BarPanel, ChartPanel, Series, save_bars, save_chart};
use style::{
    AVOID, COMPARED, DUCK, EXECUTED, GOAL, GRID, LEGEND_HEIGHT, LegendEntry, Mark, PLANNED, WALL, axes,
    draw_legend, write_picture,
};
pub use style::{check_target, tick_label};

/// A goal region: centre (plan space) and radius.
#[derive(Clone, Debug, PartialEq)]
pub struct Goal {
    /// Centre.
    pub center: Vec<f64>,
    /// Radius (m).
    pub radius: f64,
    /// A region to stay out of (drawn red), not one to reach (green).
    pub avoid: bool,
}

/// What a polyline shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathKind {
    /// Waypoints from a planner.
    Planned,
    /// Where the robot went.
    Executed,
    /// Waypoints from another planner, drawn beside [`PathKind::Planned`] for
    /// comparison (named by [`PathLabels::compared`]).
    Compared,
}

/// A sequence of plan-space points.
#[derive(Clone, Debug, PartialEq)]
pub struct Polyline {
    /// The points (each of the map's dimension).
    pub points: Vec<Vec<f64>>,
    /// Planned or executed.
    pub kind: PathKind,
}

/// A robot drawn at a pose.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotMarker {
    /// Position (plan space).
    pub position: Vec<f64>,
    /// Heading (rad, about z).
    pub heading: f64,
    /// Drawn radius (m).
    pub radius: f64,
}

/// Everything drawn in one picture.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The map.
    pub map: Map,
    /// Goal regions.
    pub goals: Vec<Goal>,
    /// Planned and executed paths.
    pub paths: Vec<Polyline>,
    /// Robots.
    pub robots: Vec<RobotMarker>,
    /// The legend's names of planned and compared waypoints.
    pub labels: PathLabels,
}

/// What the legend calls planned and compared waypoints.
#[derive(Clone, Debug, PartialEq)]
pub struct PathLabels {
    /// [`PathKind::Planned`] (default "planned waypoints").
    pub planned: String,
    /// [`PathKind::Compared`] (default "compared waypoints").
    pub compared: String,
}

impl Default for PathLabels {
    fn default() -> Self {
        Self { planned: "planned waypoints".into(), compared: "compared waypoints".into() }
    }
}

impl Scene {
    /// An empty scene on `map`.
    pub fn new(map: Map) -> Self {
        Self { map, goals: Vec::new(), paths: Vec::new(), robots: Vec::new(), labels: PathLabels::default() }
    }
}

/// Why a picture could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The output exists and overwriting was not asked for.
    #[error("{0} already exists; pass --force to overwrite it")]
    Exists(PathBuf),
    /// The extension is neither `.png` nor `.svg`.
    #[error("{0}: the output must end in .png or .svg")]
    Format(PathBuf),
    /// Drawing or writing failed.
    #[error("{path}: {message}")]
    Write {
        /// The output.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

const PX_PER_M: f64 = 100.0;
/// Room around a panel's plot for the axes' tick labels and titles (px).
const AXES: (u32, u32) = (72, 56);

/// Which two coordinates a panel shows.
#[derive(Clone, Copy)]
struct View {
    axes: (usize, usize),
    x: (f64, f64),
    y: (f64, f64),
}

impl View {
    /// The panel's size: the plot at [`PX_PER_M`] (at most 4000 px a side) and its axes.
    fn size(&self) -> (u32, u32) {
        let px = |r: f64| (r * PX_PER_M).clamp(1.0, 4000.0) as u32;
        (px(self.x.1 - self.x.0) + AXES.0, px(self.y.1 - self.y.0) + AXES.1)
    }

    /// The vertical axis's title.
    fn y_title(&self) -> &'static str {
        if self.axes.1 == 2 { "z (m)" } else { "y (m)" }
    }

    fn project(&self, p: &[f64]) -> (f64, f64) {
        (p[self.axes.0], p.get(self.axes.1).copied().unwrap_or(0.0))
    }
}

/// The panels of a scene: the map's default extent, grown to hold everything drawn.
fn views(scene: &Scene) -> Vec<View> {
    let base = match scene.map {
        Map::Duck(_) | Map::Floor => vec![
            View { axes: (0, 1), x: (-3.2, 3.2), y: (-3.2, 3.2) },
            View { axes: (0, 2), x: (-3.2, 3.2), y: (-0.2, 3.0) },
        ],
        _ => vec![View { axes: (0, 1), x: (-4.2, 4.2), y: (-4.2, 4.2) }],
    };
    let points = scene
        .paths
        .iter()
        .flat_map(|p| p.points.iter().map(|q| (q.as_slice(), 0.3)))
        .chain(scene.goals.iter().map(|g| (g.center.as_slice(), g.radius + 0.2)))
        .chain(scene.robots.iter().map(|r| (r.position.as_slice(), r.radius + 0.2)));
    let mut out = base;
    for (p, pad) in points {
        for v in &mut out {
            let (a, b) = v.project(p);
            if a.is_finite() && b.is_finite() {
                v.x = (v.x.0.min(a - pad), v.x.1.max(a + pad));
                v.y = (v.y.0.min(b - pad), v.y.1.max(b + pad));
            }
        }
    }
    // Panels stacked vertically share the horizontal extent.
    let (x0, x1) =
        out.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v.x.0), b.max(v.x.1)));
    for v in &mut out {
        v.x = (x0, x1);
    }
    out
}

fn circle_points(c: (f64, f64), r: f64) -> Vec<(f64, f64)> {
    (0..40)
        .map(|i| {
            let a = i as f64 / 40.0 * std::f64::consts::TAU;
            (c.0 + r * a.cos(), c.1 + r * a.sin())
        })
        .collect()
}

type Chart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    view: View,
    scene: &Scene,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut chart: Chart<'_, DB> = ChartBuilder::on(area)
        .margin_right(16)
        .margin_top(8)
        .x_label_area_size(AXES.1 - 8)
        .y_label_area_size(AXES.0 - 16)
        .build_cartesian_2d(view.x.0..view.x.1, view.y.0..view.y.1)
        .map_err(err)?;
    // A 1 m grid, labelled.
    let lines = |r: (f64, f64)| ((r.1.floor() - r.0.ceil()) as usize + 1).max(2);
    axes(&mut chart, "x (m)", view.y_title())
        .x_labels(lines(view.x))
        .y_labels(lines(view.y))
        .disable_mesh()
        .draw()
        .map_err(err)?;
    for k in (view.x.0.ceil() as i32)..=(view.x.1.floor() as i32) {
        let k = k as f64;
        chart
            .draw_series(std::iter::once(PathElement::new(vec![(k, view.y.0), (k, view.y.1)], GRID)))
            .map_err(err)?;
    }
    for k in (view.y.0.ceil() as i32)..=(view.y.1.floor() as i32) {
        let k = k as f64;
        chart
            .draw_series(std::iter::once(PathElement::new(vec![(view.x.0, k), (view.x.1, k)], GRID)))
            .map_err(err)?;
    }
    match &scene.map {
        Map::Walls(w) => {
            let rects = w.squares().map(|(c, h)| {
                Rectangle::new([(c[0] - h[0], c[1] - h[1]), (c[0] + h[0], c[1] + h[1])], WALL.filled())
            });
            chart.draw_series(rects).map_err(err)?;
        }
        Map::Empty(_) => {}
        Map::Floor => {
            if view.axes.1 == 2 {
                let floor = Rectangle::new([(view.x.0, view.y.0), (view.x.1, 0.0)], WALL.filled());
                chart.draw_series(std::iter::once(floor)).map_err(err)?;
            }
        }
        Map::Duck(d) => {
            if view.axes.1 == 2 {
                let floor = Rectangle::new([(view.x.0, view.y.0), (view.x.1, 0.0)], WALL.filled());
                chart.draw_series(std::iter::once(floor)).map_err(err)?;
            }
            // Each capsule as a chain of discs along its core segment.
            for c in d.pieces() {
                let discs = (0..=12).map(|i| {
                    let t = i as f64 / 12.0;
                    let p: Vec<f64> = (0..3).map(|k| c.a[k] + t * (c.b[k] - c.a[k])).collect();
                    Polygon::new(circle_points(view.project(&p), c.radius), DUCK.filled())
                });
                chart.draw_series(discs).map_err(err)?;
            }
        }
    }
    for g in &scene.goals {
        let colour = if g.avoid { AVOID } else { GOAL };
        let pts = circle_points(view.project(&g.center), g.radius);
        chart
            .draw_series(std::iter::once(Polygon::new(pts.clone(), colour.mix(0.25).filled())))
            .map_err(err)?;
        let mut ring = pts;
        ring.push(ring[0]);
        chart.draw_series(std::iter::once(PathElement::new(ring, colour.stroke_width(2)))).map_err(err)?;
    }
    for path in &scene.paths {
        let pts: Vec<(f64, f64)> = path.points.iter().map(|p| view.project(p)).collect();
        match path.kind {
            PathKind::Executed => {
                chart
                    .draw_series(std::iter::once(PathElement::new(pts, EXECUTED.stroke_width(2))))
                    .map_err(err)?;
            }
            PathKind::Planned | PathKind::Compared => {
                let colour = if path.kind == PathKind::Planned { PLANNED } else { COMPARED };
                chart
                    .draw_series(std::iter::once(PathElement::new(pts.clone(), colour.stroke_width(1))))
                    .map_err(err)?;
                chart
                    .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, colour.filled())))
                    .map_err(err)?;
            }
        }
    }
    for r in &scene.robots {
        let c = view.project(&r.position);
        let mut ring = circle_points(c, r.radius);
        ring.push(ring[0]);
        chart.draw_series(std::iter::once(Polygon::new(ring.clone(), WHITE.filled()))).map_err(err)?;
        chart.draw_series(std::iter::once(PathElement::new(ring, BLACK.stroke_width(2)))).map_err(err)?;
        if view.axes.1 == 1 {
            let tip = (c.0 + 1.6 * r.radius * r.heading.cos(), c.1 + 1.6 * r.radius * r.heading.sin());
            chart
                .draw_series(std::iter::once(PathElement::new(vec![c, tip], BLACK.stroke_width(2))))
                .map_err(err)?;
        }
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, scene: &Scene) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let vs = views(scene);
    let (top, mut rest) = root.split_vertically(LEGEND_HEIGHT);
    draw_legend(&top, &legend(scene))?;
    for v in vs {
        let (_, h) = v.size();
        let (panel, below) = rest.split_vertically(h);
        draw_panel(&panel, v, scene)?;
        rest = below;
    }
    root.present().map_err(|e| e.to_string())
}

/// The legend of what `scene` shows.
fn legend(scene: &Scene) -> Vec<LegendEntry> {
    let entry = |label: &str, color, mark| LegendEntry { label: label.into(), color, mark };
    let mut out = Vec::new();
    match scene.map {
        Map::Walls(_) => out.push(entry("walls", WALL, Mark::Patch)),
        Map::Duck(_) => out.push(entry("duck", DUCK, Mark::Patch)),
        Map::Empty(_) | Map::Floor => {}
    }
    if scene.goals.iter().any(|g| !g.avoid) {
        out.push(entry("goals", GOAL, Mark::Patch));
    }
    if scene.goals.iter().any(|g| g.avoid) {
        out.push(entry("regions to avoid", AVOID, Mark::Patch));
    }
    if scene.paths.iter().any(|p| p.kind == PathKind::Planned) {
        out.push(entry(&scene.labels.planned, PLANNED, Mark::Dots));
    }
    if scene.paths.iter().any(|p| p.kind == PathKind::Compared) {
        out.push(entry(&scene.labels.compared, COMPARED, Mark::Dots));
    }
    if scene.paths.iter().any(|p| p.kind == PathKind::Executed) {
        out.push(entry("executed trajectory", EXECUTED, Mark::Line));
    }
    if !scene.robots.is_empty() {
        out.push(entry("robot", BLACK, Mark::Line));
    }
    out
}

/// The picture's size in pixels: 100 px per metre (at most 4000 px a side), axes and
/// the legend.
pub fn image_size(scene: &Scene) -> (u32, u32) {
    let vs = views(scene);
    let w = vs.iter().map(|v| v.size().0).max().unwrap_or(0);
    (w, LEGEND_HEIGHT + vs.iter().map(|v| v.size().1).sum::<u32>())
}

/// Draws `scene` to `out` (`.png` or `.svg`); refuses to replace an existing file
/// unless `overwrite`.
pub fn save(scene: &Scene, out: &Path, overwrite: bool) -> Result<(), RenderError> {
    write_picture(out, overwrite, image_size(scene), |root| draw(root, scene), |root| draw(root, scene))
}

/// Draws `scene` into memory: `(width, height, pixels)`, the pixels row-major RGB, 3
/// bytes each (what a Gymnasium `render()` returns as `rgb_array`).
pub fn rgb(scene: &Scene) -> Result<(u32, u32, Vec<u8>), RenderError> {
    style::ensure_fonts();
    let (w, h) = image_size(scene);
    let mut pixels = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
        draw(root, scene).map_err(|message| RenderError::Write { path: "<memory>".into(), message })?;
    }
    Ok((w, h, pixels))
}

/// Draws a scalar field over a ground map's region (e.g. a learned signed distance),
/// top view at 100 px per metre: cells coloured blue where the field is positive and
/// red where negative, darker with |value| (saturating at 2 m), black where it changes
/// sign between neighbouring cells (its zero level set), and the map's true
/// obstacles outlined in grey on top. Refuses to replace a file unless `overwrite`.
pub fn save_field(
    map: &Map,
    field: &dyn Fn(&[f64]) -> f64,
    out: &Path,
    overwrite: bool,
) -> Result<(), RenderError> {
    let (lo, hi) = map.region();
    if lo.len() != 2 {
        return Err(RenderError::Write {
            path: out.to_path_buf(),
            message: format!("fields are drawn on ground maps only, not '{}'", map.name()),
        });
    }
    let cell = 0.025;
    let (nx, ny) = (((hi[0] - lo[0]) / cell).round() as usize, ((hi[1] - lo[1]) / cell).round() as usize);
    let values: Vec<f64> = (0..ny)
        .flat_map(|j| (0..nx).map(move |i| (i, j)))
        .map(|(i, j)| field(&[lo[0] + (i as f64 + 0.5) * cell, lo[1] + (j as f64 + 0.5) * cell]))
        .collect();
    let size = (
        ((hi[0] - lo[0]) * PX_PER_M) as u32 + AXES.0,
        ((hi[1] - lo[1]) * PX_PER_M) as u32 + AXES.1 + LEGEND_HEIGHT,
    );
    write_picture(
        out,
        overwrite,
        size,
        |root| draw_field(root, map, &values, (nx, ny), cell),
        |root| draw_field(root, map, &values, (nx, ny), cell),
    )
}

fn draw_field<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    map: &Map,
    values: &[f64],
    (nx, ny): (usize, usize),
    cell: f64,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (lo, hi) = map.region();
    root.fill(&WHITE).map_err(err)?;
    let (top, plot) = root.split_vertically(LEGEND_HEIGHT);
    let entry = |label: &str, color, mark| LegendEntry { label: label.into(), color, mark };
    draw_legend(
        &top,
        &[
            entry("positive", RGBColor(120, 120, 255), Mark::Patch),
            entry("negative", RGBColor(255, 120, 120), Mark::Patch),
            entry("zero level (learned surface)", BLACK, Mark::Line),
            entry("true obstacles", WALL, Mark::Line),
        ],
    )?;
    let mut chart: Chart<'_, DB> = ChartBuilder::on(&plot)
        .margin_right(16)
        .margin_top(8)
        .x_label_area_size(AXES.1 - 8)
        .y_label_area_size(AXES.0 - 16)
        .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])
        .map_err(err)?;
    axes(&mut chart, "x (m)", "y (m)").disable_mesh().draw().map_err(err)?;
    let at = |i: usize, j: usize| values[j * nx + i];
    let cells = (0..ny).flat_map(|j| (0..nx).map(move |i| (i, j))).map(|(i, j)| {
        let v = at(i, j);
        let edge = (i + 1 < nx && (at(i + 1, j) > 0.0) != (v > 0.0))
            || (j + 1 < ny && (at(i, j + 1) > 0.0) != (v > 0.0));
        let k = (v.abs() / 2.0).min(1.0);
        let shade = (255.0 * (1.0 - 0.75 * k)) as u8;
        let color = if edge {
            BLACK
        } else if v > 0.0 {
            RGBColor(shade, shade, 255)
        } else {
            RGBColor(255, shade, shade)
        };
        let (x, y) = (lo[0] + i as f64 * cell, lo[1] + j as f64 * cell);
        Rectangle::new([(x, y), (x + cell, y + cell)], color.filled())
    });
    chart.draw_series(cells).map_err(err)?;
    if let Map::Walls(w) = map {
        let outlines = w.bars().iter().map(|(c, h)| {
            Rectangle::new([(c[0] - h[0], c[1] - h[1]), (c[0] + h[0], c[1] + h[1])], WALL.stroke_width(2))
        });
        chart.draw_series(outlines).map_err(err)?;
    }
    root.present().map_err(|e| e.to_string())
}
