//! Segment clearance: exact distances when apart, penetration depth when crossing.

use sim::Map;
use sim::segment::{point_segment_distance, segment_box_2d, segment_segment_distance};

const EPS: f64 = 1e-9;

#[test]
fn segment_apart_from_a_box_measures_the_exact_gap() {
    let (c, h) = ([0.0, 0.0], [0.25, 0.25]);
    // Parallel to the right face, 0.5 away.
    assert!((segment_box_2d(&[0.75, -1.0], &[0.75, 1.0], &c, &h) - 0.5).abs() < EPS);
    // Passing the corner (0.25, 0.25) diagonally: the corner is the closest point.
    let d = segment_box_2d(&[0.25, 1.25], &[1.25, 0.25], &c, &h);
    assert!((d - point_segment_distance(&[0.25, 0.25], &[0.25, 1.25], &[1.25, 0.25])).abs() < EPS);
    assert!((d - 0.5f64.sqrt()).abs() < EPS);
}

#[test]
fn segment_crossing_a_bar_is_as_deep_as_the_way_out_along_the_bar() {
    // The walls' horizontal bar spans x in [-1.25, 1.25], y in [-0.25, 0.25].
    let walls = Map::by_name("walls").unwrap();
    let crossing_at = |x: f64| walls.segment_sdf(&[x, -1.0], &[x, 1.0]);
    // Far from the door the way out is long; it shrinks as the crossing nears the
    // bar's end at 1.25 (the door), and is positive once through the door.
    assert!((crossing_at(0.6) - -0.65).abs() < 1e-9, "{}", crossing_at(0.6));
    assert!((crossing_at(1.0) - -0.25).abs() < 1e-9);
    assert!(crossing_at(0.6) < crossing_at(0.9) && crossing_at(0.9) < crossing_at(1.2));
    assert!((crossing_at(1.5) - 0.25).abs() < 1e-9);
    // Both ends are well clear of the walls: a waypoint-only check would pass.
    assert!(walls.sdf(&[0.6, -1.0]) > 0.3 && walls.sdf(&[0.6, 1.0]) > 0.3);
}

#[test]
fn segment_sdf_is_continuous_through_contact() {
    let walls = Map::by_name("walls").unwrap();
    // Slide a vertical segment toward the bar's end at x = 1.25.
    let mut last = walls.segment_sdf(&[1.0, -1.0], &[1.0, 1.0]);
    for k in 1..=100 {
        let x = 1.0 + 0.005 * k as f64;
        let d = walls.segment_sdf(&[x, -1.0], &[x, 1.0]);
        assert!((d - last).abs() <= 0.005 + 1e-9, "jump at x = {x}: {last} -> {d}");
        last = d;
    }
}

#[test]
fn a_zero_length_segment_agrees_with_the_point_sdf_outside() {
    let walls = Map::by_name("walls").unwrap();
    for p in [[2.0, 2.0], [1.3, 0.1], [-0.4, 1.6], [3.0, 0.6]] {
        assert!((walls.segment_sdf(&p, &p) - walls.sdf(&p)).abs() < 1e-9, "{p:?}");
    }
}

#[test]
fn segment_sdf_gradient_matches_moving_the_segment() {
    let walls = Map::by_name("walls").unwrap();
    let (a, b) = ([0.9, -1.0], [1.1, 1.2]);
    let (mut ga, mut gb) = ([0.0; 2], [0.0; 2]);
    let d = walls.segment_sdf_grad(&a, &b, &mut ga, &mut gb);
    // Crossing the bar near its end: moving both ends toward the door (+x) clears it.
    assert!(d < 0.0 && ga[0] > 0.0 && gb[0] > 0.0, "{d} {ga:?} {gb:?}");
    let step = 1e-3;
    let moved = walls.segment_sdf(&[a[0] + step, a[1]], &[b[0] + step, b[1]]);
    assert!(((moved - d) - step * (ga[0] + gb[0])).abs() < 1e-6);
}

#[test]
fn segments_in_the_duck_world_meet_the_floor_and_the_duck() {
    let duck = Map::by_name("duck").unwrap();
    // Dipping under the floor: as deep as its lower end.
    assert!((duck.segment_sdf(&[2.0, 2.0, 1.0], &[2.0, -2.0, -0.2]) - -0.2).abs() < 1e-9);
    // Straight through the duck's body at the origin, both ends clear of it.
    let (a, b) = ([-2.5, 0.0, 0.6], [2.5, 0.0, 0.6]);
    assert!(duck.sdf(&a) > 0.4 && duck.sdf(&b) > 0.4);
    assert!(duck.segment_sdf(&a, &b) < -0.5);
    // Segment–segment distance on a hand case: two skew lines 1 apart.
    let d =
        segment_segment_distance(&[-1.0, 0.0, 0.0], &[1.0, 0.0, 0.0], &[0.0, -1.0, 1.0], &[0.0, 1.0, 1.0]);
    assert!((d - 1.0).abs() < 1e-12);
}

#[test]
fn the_empty_map_never_blocks_a_segment() {
    let empty = Map::by_name("empty").unwrap();
    assert_eq!(empty.segment_sdf(&[-3.0, 0.0], &[3.0, 0.0]), f64::INFINITY);
}
