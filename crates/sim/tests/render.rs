//! Pictures: formats, views, and never replacing a file silently.

use sim::render::{Goal, PathKind, Polyline, RobotMarker, Scene, image_size, save};
use sim::{Map, render::RenderError};

/// A file in a directory of this test's own (tests run in parallel).
fn tmp(name: &str) -> std::path::PathBuf {
    let test = std::thread::current().name().unwrap_or("main").replace("::", "-");
    let dir = std::env::temp_dir().join(format!("schrl-render-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    let _ = std::fs::remove_file(&p);
    p
}

fn scene(map: &str) -> Scene {
    let map = Map::by_name(map).unwrap();
    let dim = map.dim();
    let mut s = Scene::new(map);
    let p = |x: f64, y: f64| if dim == 3 { vec![x, y, 1.0] } else { vec![x, y] };
    s.goals.push(Goal { center: p(2.0, 2.0), radius: 0.5 });
    s.paths.push(Polyline { points: vec![p(1.5, -1.5), p(2.0, 0.5), p(2.0, 2.0)], kind: PathKind::Planned });
    s.paths.push(Polyline { points: vec![p(1.5, -1.5), p(1.9, 0.4), p(2.1, 1.9)], kind: PathKind::Executed });
    s.robots.push(RobotMarker { position: p(1.5, -1.5), heading: 1.0, radius: 0.1 });
    s
}

#[test]
fn writes_png_and_svg_for_every_map() {
    for map in ["walls", "empty", "duck"] {
        let png = tmp(&format!("{map}.png"));
        save(&scene(map), &png, false).unwrap();
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{map}");
        let svg = tmp(&format!("{map}.svg"));
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
    let p = tmp("keep.png");
    std::fs::write(&p, b"precious").unwrap();
    assert!(matches!(save(&scene("walls"), &p, false), Err(RenderError::Exists(_))));
    assert_eq!(std::fs::read(&p).unwrap(), b"precious");
    save(&scene("walls"), &p, true).unwrap();
    assert_ne!(std::fs::read(&p).unwrap(), b"precious");
    assert!(matches!(save(&scene("walls"), &tmp("x.jpg"), false), Err(RenderError::Format(_))));
    let dir = p.parent().unwrap();
    let leftovers: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp."))
        .collect();
    assert!(leftovers.is_empty(), "temporary files are cleaned up");
}
