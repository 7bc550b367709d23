//! Pictures: formats, views, and never replacing a file silently.

use sim::render::{Goal, PathKind, Polyline, RobotMarker, Scene, image_size, save};
use sim::{Map, render::RenderError};

fn scene(map: &str) -> Scene {
    let map = Map::by_name(map).unwrap();
    let dim = map.dim();
    let mut s = Scene::new(map);
    let p = |x: f64, y: f64| if dim == 3 { vec![x, y, 1.0] } else { vec![x, y] };
    s.goals.push(Goal { center: p(2.0, 2.0), radius: 0.5, avoid: false });
    s.goals.push(Goal { center: p(-2.0, 2.0), radius: 0.4, avoid: true });
    s.paths.push(Polyline { points: vec![p(1.5, -1.5), p(2.0, 0.5), p(2.0, 2.0)], kind: PathKind::Planned });
    s.paths.push(Polyline { points: vec![p(1.5, -1.5), p(1.9, 0.4), p(2.1, 1.9)], kind: PathKind::Executed });
    s.robots.push(RobotMarker { position: p(1.5, -1.5), heading: 1.0, radius: 0.1 });
    s
}

#[test]
fn writes_png_and_svg_for_every_map() {
    let scratch = tempfile::tempdir().unwrap();
    for map in ["walls", "empty", "duck"] {
        let png = scratch.path().join(format!("{map}.png"));
        save(&scene(map), &png, false).unwrap();
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{map}");
        let svg = scratch.path().join(format!("{map}.svg"));
        save(&scene(map), &svg, false).unwrap();
        assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    }
    // The drone's world has a top view above a side view.
    let (w, h) = image_size(&scene("duck"));
    assert!(h > w, "{w}×{h}");
}

#[test]
fn the_view_grows_to_hold_what_is_drawn() {
    let mut s = scene("walls");
    let (w0, _) = image_size(&s);
    s.paths.push(Polyline { points: vec![vec![0.0, 0.0], vec![9.0, 0.0]], kind: PathKind::Executed });
    assert!(image_size(&s).0 > w0);
}

#[test]
fn refuses_to_replace_a_file_or_guess_a_format() {
    let scratch = tempfile::tempdir().unwrap();
    let p = scratch.path().join("keep.png");
    std::fs::write(&p, b"precious").unwrap();
    assert!(matches!(save(&scene("walls"), &p, false), Err(RenderError::Exists(_))));
    assert_eq!(std::fs::read(&p).unwrap(), b"precious");
    save(&scene("walls"), &p, true).unwrap();
    assert_ne!(std::fs::read(&p).unwrap(), b"precious");
    assert!(matches!(
        save(&scene("walls"), &scratch.path().join("x.jpg"), false),
        Err(RenderError::Format(_))
    ));
    let dir = p.parent().unwrap();
    let leftovers: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp."))
        .collect();
    assert!(leftovers.is_empty(), "temporary files are cleaned up");
}

#[test]
fn tick_labels_stay_short() {
    use sim::render::tick_label;
    for (v, want) in [
        (0.0, "0"),
        (2e7, "2e7"),
        (2.5e6, "2.5e6"),
        (20000.0, "2e4"),
        (9999.0, "9999"),
        (150.0, "150"),
        (0.25, "0.25"),
        (1.0, "1"),
        (-0.5, "-0.5"),
        (1e-4, "1e-4"),
        (0.1 + 0.2, "0.3"),
    ] {
        assert_eq!(tick_label(v), want, "{v}");
    }
}

#[test]
fn charts_and_scenes_carry_axis_titles_tick_labels_and_legends() {
    let scratch = tempfile::tempdir().unwrap();
    use sim::render::{BarChart, BarPanel, ChartPanel, Series, save_bars, save_chart};
    let panel = |y: &str| ChartPanel {
        series: vec![Series {
            label: "executed runs".into(),
            points: vec![(0.0, 0.2), (2e6, 0.9)],
            band: vec![],
            colour: None,
        }],
        y_range: Some((0.0, 1.0)),
        y_label: y.into(),
        reference: None,
    };
    let svg = scratch.path().join("curve.svg");
    save_chart(&[panel("satisfaction")], "environment steps", &svg, false).unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    for want in ["environment steps", "satisfaction", "executed runs", "2e6"] {
        assert!(text.contains(want), "{want} missing from the chart's SVG");
    }
    // PNG text is drawn with the embedded font: the titles change the pixels.
    let (a, b) = (scratch.path().join("a.png"), scratch.path().join("b.png"));
    save_chart(&[panel("satisfaction")], "environment steps", &a, false).unwrap();
    save_chart(&[panel("")], "", &b, false).unwrap();
    assert_ne!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "PNG text was not drawn");

    let bars = BarChart {
        groups: vec!["seq".into(), "loop".into()],
        series: vec!["(a) SCHRL".into(), "(d) frozen planner".into()],
        x_label: "task".into(),
        panels: vec![BarPanel {
            y_label: "satisfaction (normalised)".into(),
            values: vec![vec![1.0, 0.9], vec![0.95, f64::NAN]],
            errors: Some(vec![vec![0.01, 0.05], vec![0.02, 0.0]]),
            y_range: Some((0.0, 1.15)),
        }],
    };
    let svg = scratch.path().join("bars.svg");
    save_bars(&bars, &svg, false).unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    for want in ["seq", "loop", "task", "(a) SCHRL", "(d) frozen planner", "satisfaction (normalised)"] {
        assert!(text.contains(want), "{want} missing from the bars' SVG");
    }
    save_bars(&bars, &scratch.path().join("bars.png"), false).unwrap();

    let svg = scratch.path().join("scene.svg");
    save(&scene("walls"), &svg, false).unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    for want in
        ["x (m)", "y (m)", "walls", "goals", "regions to avoid", "planned waypoints", "executed trajectory"]
    {
        assert!(text.contains(want), "{want} missing from the scene's SVG");
    }
    // Goals green, regions to avoid red.
    for colour in ["#28AA50", "#D71E28"] {
        assert!(text.to_uppercase().contains(colour), "{colour} missing from the scene's SVG");
    }
    let svg = scratch.path().join("duck.svg");
    save(&scene("duck"), &svg, false).unwrap();
    assert!(std::fs::read_to_string(&svg).unwrap().contains("z (m)"), "the side view's axis");
}

#[test]
fn a_series_keeps_its_colour_in_a_panel_that_lacks_the_others() {
    let scratch = tempfile::tempdir().unwrap();
    // Fig. 3's Loop panel without HTLTL drew TLTL in HTLTL's blue.
    use sim::render::{ChartPanel, Series, save_chart};
    let panel = |colour| ChartPanel {
        series: vec![Series {
            label: "tltl".into(),
            points: vec![(0.0, -1.0), (1.0, -2.0)],
            band: vec![],
            colour,
        }],
        y_range: None,
        y_label: "spec score".into(),
        reference: None,
    };
    let (third, first) = (scratch.path().join("third.svg"), scratch.path().join("first.svg"));
    save_chart(&[panel(Some(2))], "environment steps", &third, false).unwrap();
    save_chart(&[panel(None)], "environment steps", &first, false).unwrap();
    // The palette's third colour is the goals' green, its first the executed orange.
    let third = std::fs::read_to_string(&third).unwrap().to_uppercase();
    assert!(third.contains("#28AA50"), "the series is not in the palette's third colour");
    assert!(!std::fs::read_to_string(&first).unwrap().to_uppercase().contains("#28AA50"));
}

#[test]
fn rgb_renders_in_memory_what_a_png_would_show() {
    let scene = scene("walls");
    let (w, h, pixels) = sim::render::rgb(&scene).unwrap();
    assert_eq!((w, h), image_size(&scene));
    assert_eq!(pixels.len(), w as usize * h as usize * 3);
    // Background, walls, goals and paths: more than one colour.
    let first = &pixels[..3];
    let different = pixels.chunks(3).filter(|p| p != &first).count();
    assert!(different > pixels.len() / 3 / 20, "{different} pixels differ from the first");
}
