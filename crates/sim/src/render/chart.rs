//! Charts: line charts of training curves and grouped bar charts of results, each
//! panel with axis titles, tick labels and a legend.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::RenderError;
use super::style::{
    DUCK, EXECUTED, GOAL, LEGEND_HEIGHT, LegendEntry, Mark, PLANNED, WALL, axes, draw_legend, text,
    write_picture,
};

/// Series colours in order: orange, blue, green, grey, yellow.
const PALETTE: [RGBColor; 5] = [EXECUTED, PLANNED, GOAL, WALL, DUCK];

/// One line of a chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Its name in the legend.
    pub label: String,
    /// Its `(x, y)` points; non-finite ones are skipped.
    pub points: Vec<(f64, f64)>,
    /// A band drawn under the line in its colour, light: `(x, low, high)` (e.g. mean ±
    /// std over seeds); empty: none. Non-finite entries are skipped.
    pub band: Vec<(f64, f64, f64)>,
    /// Its place in the palette; `None`: its place in the panel. Set it to keep a
    /// method's colour across panels that lack some methods.
    pub colour: Option<usize>,
}

impl Series {
    fn color(&self, position: usize) -> RGBColor {
        PALETTE[self.colour.unwrap_or(position) % PALETTE.len()]
    }
}

/// One panel of a line chart.
#[derive(Clone, Debug, PartialEq)]
pub struct ChartPanel {
    /// The lines, drawn in the palette's colours (orange, blue, green, grey, yellow).
    pub series: Vec<Series>,
    /// Fixed y range, e.g. `(0, 1)` for rates; `None`: the data's, and the reference's.
    pub y_range: Option<(f64, f64)>,
    /// The y axis's title.
    pub y_label: String,
    /// A dashed black line across the panel at this y, under the series (e.g. 0 for a
    /// score whose sign is a verdict), drawn where it is in range; `None`: none.
    pub reference: Option<f64>,
}

/// Panel size of line charts (px).
const PANEL: (u32, u32) = (820, 280);

/// Writes line-chart panels stacked top to bottom to `out` (`.png` or `.svg`): each
/// with its legend above it, its y title, tick labels, and `x_label` under the x axis
/// shared by all. Refuses to replace a file unless `overwrite`.
pub fn save_chart(
    panels: &[ChartPanel],
    x_label: &str,
    out: &Path,
    overwrite: bool,
) -> Result<(), RenderError> {
    let size = (PANEL.0, PANEL.1 * panels.len().max(1) as u32);
    write_picture(
        out,
        overwrite,
        size,
        |root| draw_chart(root, panels, x_label),
        |root| draw_chart(root, panels, x_label),
    )
}

/// The extent of `values`, widened when empty or flat.
fn extent(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) =
        values.filter(|v| v.is_finite()).fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    if lo > hi {
        (lo, hi) = (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        (lo, hi) = (lo - 0.5, hi + 0.5);
    }
    (lo, hi)
}

fn legend(entries: impl Iterator<Item = (String, RGBColor)>, mark: Mark) -> Vec<LegendEntry> {
    entries.map(|(label, color)| LegendEntry { label, color, mark }).collect()
}

/// A panel's y range: its fixed one, or its lines' and bands' values and its
/// reference line's. With the reference out of range, plotters would clip the line
/// onto the frame, where it reads as if the curves reached it.
fn y_extent(panel: &ChartPanel) -> (f64, f64) {
    if let Some(range) = panel.y_range {
        return range;
    }
    let values = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1).chain(s.band.iter().flat_map(|b| [b.1, b.2])));
    extent(values.chain(panel.reference.filter(|y| y.is_finite())))
}

fn draw_chart<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    panels: &[ChartPanel],
    x_label: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (panel, area) in panels.iter().zip(areas) {
        let (top, plot) = area.split_vertically(LEGEND_HEIGHT);
        let entries = panel.series.iter().enumerate().map(|(i, s)| (s.label.clone(), s.color(i)));
        draw_legend(&top, &legend(entries, Mark::Line))?;
        let (x0, x1) = extent(panel.series.iter().flat_map(|s| s.points.iter().map(|p| p.0)));
        let reference = panel.reference.filter(|y| y.is_finite());
        let (y0, y1) = y_extent(panel);
        let pad = 0.05 * (y1 - y0);
        let mut chart = ChartBuilder::on(&plot)
            .margin_left(12)
            .margin_right(20)
            .margin_bottom(6)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(err)?;
        axes(&mut chart, x_label, &panel.y_label).draw().map_err(err)?;
        if let Some(y) = reference.filter(|y| (y0 - pad..=y1 + pad).contains(y)) {
            let line =
                plotters::element::DashedPathElement::new([(x0, y), (x1, y)], 6, 4, BLACK.stroke_width(1));
            chart.draw_series(std::iter::once(line)).map_err(err)?;
        }
        for (i, s) in panel.series.iter().enumerate() {
            let band: Vec<(f64, f64, f64)> = s
                .band
                .iter()
                .copied()
                .filter(|b| b.0.is_finite() && b.1.is_finite() && b.2.is_finite())
                .collect();
            if band.len() > 1 {
                let outline: Vec<(f64, f64)> =
                    band.iter().map(|b| (b.0, b.2)).chain(band.iter().rev().map(|b| (b.0, b.1))).collect();
                let fill = s.color(i).mix(0.2).filled();
                chart.draw_series(std::iter::once(Polygon::new(outline, fill))).map_err(err)?;
            }
        }
        for (i, s) in panel.series.iter().enumerate() {
            let line: Vec<(f64, f64)> =
                s.points.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
            let style = s.color(i).stroke_width(2);
            chart.draw_series(std::iter::once(PathElement::new(line, style))).map_err(err)?;
        }
    }
    root.present().map_err(err)
}

/// One panel of a grouped bar chart.
#[derive(Clone, Debug, PartialEq)]
pub struct BarPanel {
    /// The y axis's title.
    pub y_label: String,
    /// Bar heights, `[series][group]`; a non-finite value draws no bar.
    pub values: Vec<Vec<f64>>,
    /// Error-bar half-lengths in the same layout (e.g. a std), if any.
    pub errors: Option<Vec<Vec<f64>>>,
    /// Fixed y range; `None`: from 0 to the tallest bar.
    pub y_range: Option<(f64, f64)>,
}

/// A grouped bar chart: one bar per series in each group, panels stacked.
#[derive(Clone, Debug, PartialEq)]
pub struct BarChart {
    /// Group names along the x axis.
    pub groups: Vec<String>,
    /// Series names, in the legend.
    pub series: Vec<String>,
    /// Title of the x axis, under the group names (empty: none).
    pub x_label: String,
    /// The panels (each its own measure).
    pub panels: Vec<BarPanel>,
}

/// Writes `chart` to `out` (`.png` or `.svg`); refuses to replace a file unless
/// `overwrite`.
pub fn save_bars(chart: &BarChart, out: &Path, overwrite: bool) -> Result<(), RenderError> {
    let width = (140 * chart.groups.len().max(1) as u32 + 120).max(PANEL.0);
    let size = (width, LEGEND_HEIGHT + PANEL.1 * chart.panels.len().max(1) as u32);
    write_picture(out, overwrite, size, |root| draw_bars(root, chart), |root| draw_bars(root, chart))
}

fn draw_bars<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, bars: &BarChart) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let (top, rest) = root.split_vertically(LEGEND_HEIGHT);
    let entries = bars.series.iter().enumerate().map(|(i, l)| (l.clone(), PALETTE[i % PALETTE.len()]));
    draw_legend(&top, &legend(entries, Mark::Patch))?;
    let n_groups = bars.groups.len().max(1);
    let n_series = bars.series.len().max(1);
    let width = 0.8 / n_series as f64;
    for (panel, area) in bars.panels.iter().zip(rest.split_evenly((bars.panels.len().max(1), 1))) {
        let tallest = panel
            .values
            .iter()
            .zip(0..)
            .flat_map(|(vs, s)| {
                vs.iter().enumerate().map(move |(g, v)| {
                    v + panel
                        .errors
                        .as_ref()
                        .and_then(|e| e.get(s))
                        .and_then(|e| e.get(g))
                        .copied()
                        .unwrap_or(0.0)
                })
            })
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max);
        let (y0, y1) = panel.y_range.unwrap_or((0.0, if tallest > 0.0 { 1.1 * tallest } else { 1.0 }));
        let mut chart = ChartBuilder::on(&area)
            .margin_left(12)
            .margin_right(20)
            .margin_top(8)
            // Room for the group names, and the axis title under them.
            .x_label_area_size(if bars.x_label.is_empty() { 30 } else { 50 })
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..n_groups as f64, y0..y1)
            .map_err(err)?;
        axes(&mut chart, &bars.x_label, &panel.y_label).disable_x_mesh().x_labels(0).draw().map_err(err)?;
        for (s, values) in panel.values.iter().enumerate() {
            let color = PALETTE[s % PALETTE.len()];
            for (g, v) in values.iter().enumerate().filter(|(_, v)| v.is_finite()) {
                let x = g as f64 + 0.1 + s as f64 * width;
                let bar = Rectangle::new([(x, y0), (x + width * 0.92, v.min(y1))], color.filled());
                chart.draw_series(std::iter::once(bar)).map_err(err)?;
                let e = panel.errors.as_ref().and_then(|e| e.get(s)).and_then(|e| e.get(g)).copied();
                if let Some(e) = e.filter(|e| e.is_finite() && *e > 0.0) {
                    let c = x + width * 0.46;
                    let (lo, hi) = ((v - e).max(y0), (v + e).min(y1));
                    let whisker = [
                        vec![(c, lo), (c, hi)],
                        vec![(c - width * 0.2, lo), (c + width * 0.2, lo)],
                        vec![(c - width * 0.2, hi), (c + width * 0.2, hi)],
                    ];
                    chart
                        .draw_series(whisker.into_iter().map(|p| PathElement::new(p, BLACK.stroke_width(1))))
                        .map_err(err)?;
                }
            }
        }
        // Group names centred under their bars.
        let style = text(14).pos(plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Center,
            plotters::style::text_anchor::VPos::Top,
        ));
        for (g, name) in bars.groups.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(g as f64 + 0.5, y0));
            let (ax, ay) = area.get_base_pixel();
            area.draw(&Text::new(name.clone(), (px - ax, py - ay + 8), style.clone())).map_err(err)?;
        }
    }
    root.present().map_err(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CRM's Fig. 3 panel (scores −4.1 to −3.3, a reference at 0) drew its dashed line
    /// on the top of the frame, as if the curves reached 0.
    #[test]
    fn a_reference_out_of_the_datas_range_stretches_the_axis_to_it() {
        let series = Series {
            label: "crm".into(),
            points: vec![(1.0, -4.1), (2.0, -3.3)],
            band: vec![],
            colour: None,
        };
        let mut panel =
            ChartPanel { series: vec![series], y_range: None, y_label: "score".into(), reference: Some(0.0) };
        assert_eq!(y_extent(&panel), (-4.1, 0.0));
        panel.reference = None;
        assert_eq!(y_extent(&panel), (-4.1, -3.3));
        panel.y_range = Some((-5.0, 1.0));
        assert_eq!(y_extent(&panel), (-5.0, 1.0), "a fixed range is kept");
    }
}
