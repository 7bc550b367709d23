//! What every picture shares: the palette, the embedded font, tick labels, the legend
//! strip, and writing a file atomically.
//!
//! Text in PNGs is drawn with DejaVu Sans embedded in the binary (the `dejavu`
//! crate, through plotters' `ab_glyph` backend), so pictures read the same on a
//! machine without system fonts; SVGs name the font and leave drawing it to the
//! viewer.

use std::path::Path;
use std::sync::Once;

use plotters::chart::{ChartContext, MeshStyle};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;

use super::RenderError;

/// Walls and other obstacles.
pub(crate) const WALL: RGBColor = RGBColor(90, 90, 96);
/// The Drone world's duck.
pub(crate) const DUCK: RGBColor = RGBColor(240, 200, 40);
/// Goals.
pub(crate) const GOAL: RGBColor = RGBColor(40, 170, 80);
/// Regions a spec says to stay out of.
pub(crate) const AVOID: RGBColor = RGBColor(215, 30, 40);
/// Planned waypoints.
pub(crate) const PLANNED: RGBColor = RGBColor(40, 90, 220);
/// Another planner's waypoints.
pub(crate) const COMPARED: RGBColor = RGBColor(160, 50, 170);
/// Executed trajectories.
pub(crate) const EXECUTED: RGBColor = RGBColor(240, 120, 20);
/// Grid lines.
pub(crate) const GRID: RGBColor = RGBColor(232, 232, 236);
/// Text.
pub(crate) const INK: RGBColor = RGBColor(30, 30, 34);

/// The font family every text element names.
pub(crate) const FONT: &str = "sans-serif";
/// Height of the legend strip above a picture (px).
pub(crate) const LEGEND_HEIGHT: u32 = 28;

/// Registers the embedded DejaVu Sans as [`FONT`] (once per process).
pub(crate) fn ensure_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TrueType font shipped by the `dejavu` crate.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// Text of `size` px in the picture's font.
pub(crate) fn text(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().color(&INK)
}

/// A tick label that stays short: integers as they are up to 9999, larger and smaller
/// magnitudes as `2e7` / `2.5e6` / `1e-4`, other numbers with at most three
/// significant decimals and no trailing zeros.
pub fn tick_label(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    let a = v.abs();
    if a < 1e-12 {
        return "0".into();
    }
    if !(1e-3..1e4).contains(&a) {
        let e = a.log10().floor();
        let m = v / 10f64.powf(e);
        // Rounding the mantissa may carry it to 10.
        let (m, e) = if (m.abs() * 100.0).round() >= 1000.0 { (m / 10.0, e + 1.0) } else { (m, e) };
        return format!("{}e{}", trim(&format!("{m:.2}")), e as i32);
    }
    let decimals = (3 - a.log10().floor() as i32 - 1).clamp(0, 6) as usize;
    trim(&format!("{v:.decimals$}"))
}

/// [`tick_label`] as a mesh's label formatter.
fn tick(v: &f64) -> String {
    tick_label(*v)
}

/// A chart's mesh with this project's axis style: titles `x` and `y` (an empty title
/// draws none), short tick labels, the picture's font, light grid lines.
pub(crate) fn axes<'a, 'b, DB: DrawingBackend>(
    chart: &'b mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x: &str,
    y: &str,
) -> MeshStyle<'a, 'b, RangedCoordf64, RangedCoordf64, DB> {
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(x)
        .y_desc(y)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .label_style(text(13))
        .axis_desc_style(text(14))
        .light_line_style(TRANSPARENT)
        .bold_line_style(GRID);
    mesh
}

fn trim(s: &str) -> String {
    if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s.to_string() }
}

/// How a legend entry shows its series.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mark {
    /// A short line.
    Line,
    /// A line with dots (waypoints).
    Dots,
    /// A filled square (regions, bars).
    Patch,
}

/// One entry of a legend.
pub(crate) struct LegendEntry {
    pub label: String,
    pub color: RGBColor,
    pub mark: Mark,
}

/// Draws `entries` left to right in `area` (a strip [`LEGEND_HEIGHT`] px tall).
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let style = text(14);
    let y = LEGEND_HEIGHT as i32 / 2;
    let mut x = 10;
    for e in entries {
        match e.mark {
            Mark::Line => area.draw(&PathElement::new(vec![(x, y), (x + 22, y)], e.color.stroke_width(3))),
            Mark::Dots => {
                area.draw(&PathElement::new(vec![(x, y), (x + 22, y)], e.color.stroke_width(1)))
                    .map_err(err)?;
                area.draw(&Circle::new((x + 4, y), 3, e.color.filled())).map_err(err)?;
                area.draw(&Circle::new((x + 18, y), 3, e.color.filled()))
            }
            Mark::Patch => area.draw(&Rectangle::new([(x + 3, y - 7), (x + 19, y + 7)], e.color.filled())),
        }
        .map_err(err)?;
        let (w, _) = area.estimate_text_size(&e.label, &style).map_err(err)?;
        area.draw(&Text::new(e.label.clone(), (x + 28, y - 8), style.clone())).map_err(err)?;
        x += 28 + w as i32 + 18;
    }
    Ok(())
}

/// Writes a picture of `size` pixels to `out` through a temporary file and a rename,
/// choosing the backend by extension; refuses to replace a file unless `overwrite`.
/// Checks that a picture can be written to `out` (a `.png` or `.svg` name in an
/// existing directory, not an existing file unless `overwrite`) and returns its
/// format; callers check before long work, so a bad `--out` fails at once.
pub fn check_target(out: &Path, overwrite: bool) -> Result<&'static str, RenderError> {
    let ext = match out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("png") => "png",
        Some("svg") => "svg",
        _ => return Err(RenderError::Format(out.to_path_buf())),
    };
    if out.exists() && !overwrite {
        return Err(RenderError::Exists(out.to_path_buf()));
    }
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        return Err(RenderError::Write {
            path: out.to_path_buf(),
            message: format!("the directory {} does not exist", dir.display()),
        });
    }
    Ok(ext)
}

pub(crate) fn write_picture(
    out: &Path,
    overwrite: bool,
    size: (u32, u32),
    png: impl FnOnce(DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
    svg: impl FnOnce(DrawingArea<SVGBackend, Shift>) -> Result<(), String>,
) -> Result<(), RenderError> {
    ensure_fonts();
    let ext = check_target(out, overwrite)?;
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("picture");
    let tmp = out.with_file_name(format!(".{stem}.{}.tmp.{ext}", std::process::id()));
    let result = if ext == "png" {
        png(BitMapBackend::new(&tmp, size).into_drawing_area())
    } else {
        svg(SVGBackend::new(&tmp, size).into_drawing_area())
    };
    let fail = |message: String| RenderError::Write { path: out.to_path_buf(), message };
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(e));
    }
    std::fs::rename(&tmp, out).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        fail(e.to_string())
    })
}
