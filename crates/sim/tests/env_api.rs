//! The goal-conditioned API: reward, reach, truncation, determinism, bad input.

use sim::{Env, EnvError, Map, Robot, VecEnv, make_env};

#[test]
fn spaces_match_the_paper() {
    for (robot, obs, act, plan) in
        [(Robot::Point, 14, 2, 2), (Robot::Car, 26, 2, 2), (Robot::Drone, 18, 18, 3)]
    {
        let env = make_env(robot, robot.default_map()).unwrap();
        assert_eq!(env.observation_space().dim(), obs, "{robot}");
        assert_eq!(env.action_space().dim(), act, "{robot}");
        assert_eq!(env.plan_dim(), plan, "{robot}");
    }
}

#[test]
fn reward_is_distance_decrease_plus_reach_bonus_once() {
    let mut env = make_env(Robot::Point, Map::by_name("empty").unwrap()).unwrap();
    env.reset(0, Some(&[0.0, 0.0])).unwrap();
    env.set_goal(&[0.5, 0.0]).unwrap();
    let mut total = 0.0;
    let mut reaches = 0;
    let mut last = 0.5;
    for _ in 0..200 {
        // Drive toward the goal whatever the heading: turn, then push.
        let obs = env.reset_free_obs();
        let (gx, gy) = (obs[12], obs[13]);
        let action = [if gx > 0.0 { 1.0 } else { -1.0 }, (gy.atan2(gx.abs())).clamp(-1.0, 1.0)];
        let (_, s) = env.step(&action).unwrap();
        let p = env.position();
        let d = (p[0] - 0.5).hypot(p[1]);
        let expect = last - d + if s.reached { 20.0 } else { 0.0 };
        assert!((s.reward - expect).abs() < 1e-12);
        if s.reached {
            assert!(d <= 0.3);
        }
        reaches += s.reached as usize;
        total += s.reward;
        last = d;
    }
    assert_eq!(reaches, 1, "reaching pays once per goal");
    assert!(total > 20.0);
    env.set_goal(&[0.0, 0.0]).unwrap();
    let (_, s) = env.step(&[0.0, 0.0]).unwrap();
    assert!(!s.reached || env.position()[0].hypot(env.position()[1]) <= 0.3);
}

trait ObsNow {
    fn reset_free_obs(&self) -> Vec<f64>;
}

impl ObsNow for Box<dyn Env> {
    fn reset_free_obs(&self) -> Vec<f64> {
        let mut o = vec![0.0; self.observation_space().dim()];
        self.observe(&mut o);
        o
    }
}

#[test]
fn truncation_at_the_step_limit() {
    let mut env = make_env(Robot::Car, Map::by_name("walls").unwrap()).unwrap();
    env.reset(1, None).unwrap();
    env.set_max_steps(5);
    for i in 1..=5 {
        let (_, s) = env.step(&[0.0, 0.0]).unwrap();
        assert_eq!(s.truncated, i == 5);
    }
}

#[test]
fn same_seed_same_trajectory_different_seed_different() {
    let run = |seed: u64| {
        let mut v = VecEnv::new(Robot::Car, Map::by_name("walls").unwrap(), 4, seed).unwrap();
        let mut obs = vec![0.0; 4 * v.obs_dim()];
        let mut steps = vec![Default::default(); 4];
        let actions: Vec<f64> = (0..8).map(|i| ((i * 37 % 11) as f64 / 5.5) - 1.0).collect();
        for _ in 0..200 {
            v.step_all(&actions, &mut obs, &mut steps).unwrap();
        }
        obs
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3), run(4));
}

#[test]
fn bad_input_is_an_error_and_leaves_the_state_alone() {
    let mut env = make_env(Robot::Point, Map::by_name("walls").unwrap()).unwrap();
    env.reset(0, Some(&[2.0, 2.0])).unwrap();
    let before = env.position().to_vec();
    assert!(matches!(env.step(&[1.0]), Err(EnvError::ActionLength { expected: 2, got: 1, .. })));
    assert!(matches!(env.step(&[f64::NAN, 0.0]), Err(EnvError::NonFiniteAction { index: 0, .. })));
    assert!(matches!(env.step(&[0.0, f64::INFINITY]), Err(EnvError::NonFiniteAction { index: 1, .. })));
    assert_eq!(env.position(), &before[..]);
    assert_eq!(env.steps(), 0);
    assert!(matches!(env.set_goal(&[1.0, 2.0, 3.0]), Err(EnvError::BadPoint { .. })));
    assert!(matches!(env.reset(0, Some(&[0.0, 0.0])), Err(EnvError::StartBlocked { .. })));
    assert!("tank".parse::<Robot>().is_err());
    assert!(Map::by_name("maze").is_none());
    assert!(matches!(
        make_env(Robot::Drone, Map::by_name("walls").unwrap()),
        Err(EnvError::MapMismatch { .. })
    ));
    let err = "tank".parse::<Robot>().unwrap_err().to_string();
    assert!(err.contains("unknown robot 'tank'"), "{err}");
}

#[test]
fn walls_sdf_is_exact_and_its_gradient_matches() {
    let map = Map::by_name("walls").unwrap();
    // Door between the centre bar (ends at 1.25) and the outer bar (starts at 2.75).
    assert!((map.sdf(&[2.0, 0.0]) - 0.75).abs() < 1e-12);
    assert!((map.sdf(&[0.6, 0.6]) - 0.35).abs() < 1e-12, "{}", map.sdf(&[0.6, 0.6]));
    assert!(map.sdf(&[0.0, 0.1]) < 0.0);
    for p in [[1.7, 0.9], [0.4, 2.2], [-3.0, -0.6], [1.9, 0.1], [0.1, 0.2], [3.9, 0.3]] {
        let mut g = [0.0; 3];
        map.sdf_grad(&p, &mut g);
        for i in 0..2 {
            let mut q = p;
            q[i] += 1e-7;
            let up = map.sdf(&q);
            q[i] -= 2e-7;
            let fd = (up - map.sdf(&q)) / 2e-7;
            assert!((fd - g[i]).abs() < 1e-5, "{p:?}[{i}]: {} vs {fd}", g[i]);
        }
    }
    let duck = Map::by_name("duck").unwrap();
    assert!((duck.sdf(&[3.0, 3.0, 0.7]) - 0.7).abs() < 1e-12, "floor");
    assert!(duck.sdf(&[0.0, 0.0, 0.5]) < 0.0, "inside the body");
    assert!(duck.sdf(&[0.45, 0.0, 1.45]) < 0.0, "inside the head");
    assert!((duck.sdf(&[0.45, 0.0, 2.35]) - 0.5).abs() < 1e-12, "0.5 above the head");
}

#[test]
fn duck_world_distance_is_the_nearer_of_floor_and_duck_everywhere() {
    // The map skips the duck when its bounding sphere is farther than the floor;
    // that shortcut must never change the answer.
    let world = sim::DuckWorld::new();
    let map = Map::Duck(world.clone());
    let mut s = 12345u64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..20_000 {
        let p = [next() * 8.0 - 4.0, next() * 8.0 - 4.0, next() * 4.0 - 0.5];
        let mut g = [0.0; 3];
        let want = p[2].min(world.duck_sdf(&p, &mut g));
        assert_eq!(map.sdf(&p), want, "{p:?}");
    }
}

#[test]
fn saved_state_restores_bit_for_bit() {
    for robot in Robot::NATIVE {
        let mut env = make_env(robot, robot.default_map()).unwrap();
        env.reset(7, None).unwrap();
        let act = vec![0.3; env.action_space().dim()];
        for _ in 0..25 {
            env.step(&act).unwrap();
        }
        let saved = env.save_state();
        let run = |env: &mut Box<dyn Env>| -> Vec<f64> {
            let mut out = Vec::new();
            for k in 0..40 {
                let a: Vec<f64> = (0..act.len()).map(|i| ((k * 7 + i) as f64 * 0.37).sin()).collect();
                let (obs, s) = env.step(&a).unwrap();
                out.extend(obs);
                out.push(s.reward);
            }
            out.extend(env.sample_goal());
            out
        };
        let first = run(&mut env);
        let mut fresh = make_env(robot, robot.default_map()).unwrap();
        fresh.restore_state(&saved).unwrap();
        assert_eq!(fresh.steps(), 25, "{robot}");
        assert_eq!(run(&mut fresh), first, "{robot}: restored run differs");
    }
}

#[test]
fn goal_origin_is_where_the_goal_was_set_and_survives_a_restore() {
    for robot in Robot::NATIVE {
        let mut env = make_env(robot, robot.default_map()).unwrap();
        env.reset(3, None).unwrap();
        assert_eq!(env.goal_origin(), env.position(), "{robot}: a reset's goal is set at the start");
        let act = vec![0.5; env.action_space().dim()];
        for _ in 0..30 {
            env.step(&act).unwrap();
        }
        let here = env.position().to_vec();
        assert_ne!(env.goal_origin(), &here[..], "{robot} should have moved");
        let goal = env.sample_goal();
        env.set_goal(&goal).unwrap();
        assert_eq!(env.goal_origin(), &here[..], "{robot}");
        for _ in 0..10 {
            env.step(&act).unwrap();
        }
        let saved = env.save_state();
        let mut fresh = make_env(robot, robot.default_map()).unwrap();
        fresh.restore_state(&saved).unwrap();
        assert_eq!(fresh.goal_origin(), &here[..], "{robot}");
        // A state saved before the origin was kept: the robot's position stands in.
        let mut old: serde_json::Value = serde_json::from_str(&saved).unwrap();
        old.as_object_mut().unwrap().remove("goal_origin").expect("saved states hold the origin");
        fresh.restore_state(&old.to_string()).unwrap();
        assert_eq!(fresh.goal_origin(), fresh.position(), "{robot}");
    }
}

#[test]
fn restoring_another_robots_state_is_an_error_and_changes_nothing() {
    let point = make_env(Robot::Point, Map::by_name("empty").unwrap()).unwrap();
    let mut car = make_env(Robot::Car, Map::by_name("empty").unwrap()).unwrap();
    let before = car.save_state();
    let err = car.restore_state(&point.save_state()).unwrap_err();
    assert!(matches!(err, EnvError::BadState { robot: "car", .. }), "{err}");
    let err = car.restore_state("{not json").unwrap_err();
    assert!(err.to_string().contains("cannot restore a car"), "{err}");
    assert_eq!(car.save_state(), before);
}

#[test]
fn floor_map_is_open_space_for_the_drone() {
    let map = Map::by_name("floor").unwrap();
    assert_eq!(map.dim(), 3);
    assert_eq!(map.sdf(&[5.0, -3.0, 1.25]), 1.25);
    let mut env = make_env(Robot::Drone, map).unwrap();
    env.reset(1, Some(&[0.0, 0.0, 1.0])).unwrap();
    assert!(make_env(Robot::Point, Map::by_name("floor").unwrap()).is_err());
}

#[cfg(not(feature = "mujoco"))]
#[test]
fn doggo_without_the_mujoco_feature_says_how_to_enable_it() {
    let robot: Robot = "doggo".parse().unwrap();
    assert!(!robot.is_available());
    let err = make_env(robot, Map::by_name("walls").unwrap()).err().unwrap();
    let msg = err.to_string();
    assert!(msg.contains("scripts/setup-mujoco.sh") && msg.contains("--features mujoco"), "{msg}");
}

#[test]
fn a_reach_radius_that_is_not_positive_and_finite_is_refused() {
    let mut env = make_env(Robot::Point, Map::by_name("empty").unwrap()).unwrap();
    for bad in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        let e = env.set_reach_radius(bad).unwrap_err();
        assert!(matches!(e, EnvError::BadReachRadius { .. }), "{e}");
        assert!(e.to_string().contains("positive finite"), "{e}");
    }
    assert_eq!(env.reach_radius(), 0.3, "a refused radius changes nothing");
}

#[test]
fn near_goals_are_free_beyond_the_reach_radius_and_within_the_ball() {
    for robot in [Robot::Point, Robot::Car, Robot::Drone] {
        let map = robot.default_map();
        let mut env = make_env(robot, map.clone()).unwrap();
        env.reset(3, None).unwrap();
        let at = env.position().to_vec();
        let dist = |g: &[f64]| g.iter().zip(&at).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
        let goals: Vec<Vec<f64>> = (0..200).map(|_| env.sample_goal_within(1.0)).collect();
        for g in &goals {
            assert!(dist(g) <= 1.0 && dist(g) > env.reach_radius(), "{robot}: {g:?} from {at:?}");
            assert!(map.sdf(g) > env.radius(), "{robot}: {g:?} is not free");
        }
        // Uniform in the ball beyond the reach radius r0: in d dimensions the mean
        // distance is d/(d+1) (1 − r0^(d+1)) / (1 − r0^d).
        let (d, r0) = (at.len() as f64, env.reach_radius());
        let expected = d / (d + 1.0) * (1.0 - r0.powf(d + 1.0)) / (1.0 - r0.powf(d));
        let mean = goals.iter().map(|g| dist(g)).sum::<f64>() / goals.len() as f64;
        assert!((mean - expected).abs() < 0.05, "{robot}: mean distance {mean}, uniform {expected}");
        // Far from every free point, the draw falls back to anywhere on the map.
        let anywhere = env.sample_goal_within(1e-3);
        assert!(map.sdf(&anywhere) > env.radius(), "{robot}");
    }
}

/// The track offset is the nearest point of the segment origin → goal less the
/// robot's position, turned into its heading frame (forward, left; up unturned), and
/// appended after the robot's own observation, which it leaves alone.
#[test]
fn track_observation_is_the_offset_from_the_segment_in_the_heading_frame() {
    for (robot, map, start, origin, goal) in [
        (Robot::Point, "empty", vec![0.0, 0.0], vec![-1.0, 1.0], vec![3.0, 1.0]),
        (Robot::Car, "empty", vec![0.5, -0.5], vec![2.5, -2.0], vec![2.5, 2.0]),
        (Robot::Drone, "floor", vec![0.0, 0.0, 1.0], vec![-1.0, 0.0, 2.0], vec![1.0, 0.0, 2.0]),
    ] {
        let mut plain = make_env(robot, Map::by_name(map).unwrap()).unwrap();
        let mut env = make_env(robot, Map::by_name(map).unwrap()).unwrap();
        assert!(!env.track_observation(), "{robot}: off by default");
        env.set_track_observation(true);
        let own = plain.observation_space().dim();
        assert_eq!(env.observation_space().dim(), own + env.plan_dim(), "{robot}");
        for e in [&mut plain, &mut env] {
            e.reset(3, Some(&start)).unwrap();
            e.set_goal(&goal).unwrap();
            e.set_goal_origin(&origin).unwrap();
        }
        // Off the segment and past its origin's end, after a few steps.
        for _ in 0..5 {
            let action = vec![0.3; env.action_space().dim()];
            plain.step(&action).unwrap();
            let (obs, _) = env.step(&action).unwrap();
            let want = plain.reset_free_obs();
            assert_eq!(&obs[..own], &want[..], "{robot}: the robot's own observation is unchanged");
            let p = env.position().to_vec();
            let s = sim::segment::closest_fraction(&p, &origin, &goal);
            let d: Vec<f64> = (0..p.len()).map(|k| origin[k] + s * (goal[k] - origin[k]) - p[k]).collect();
            let (sin, cos) = env.heading().sin_cos();
            let (fwd, left) = (cos * d[0] + sin * d[1], -sin * d[0] + cos * d[1]);
            let tail = &obs[own..];
            assert!((tail[0] - fwd).abs() < 1e-12 && (tail[1] - left).abs() < 1e-12, "{robot}: {tail:?}");
            assert_eq!(&tail[2..], &d[2..], "{robot}: height unturned");
            let off = sim::segment::point_segment_distance(&p, &origin, &goal);
            let norm = tail.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!((norm - off).abs() < 1e-9 && off > 0.1, "{robot}: {norm} against {off}");
        }
        // Set goals start their track where the robot stands: no offset.
        env.set_goal(&goal).unwrap();
        let obs = env.reset_free_obs();
        assert!(obs[own..].iter().all(|x| x.abs() < 1e-12), "{robot}: {:?}", &obs[own..]);
        assert!(env.set_goal_origin(&[f64::NAN; 3][..env.plan_dim()]).is_err());
        let mut short = vec![0.0; own];
        assert!(matches!(
            env.step_into(&vec![0.0; env.action_space().dim()], &mut short),
            Err(EnvError::ObservationLength { .. })
        ));
        env.set_track_observation(false);
        assert_eq!(env.observation_space().dim(), own, "{robot}: off again");
    }
}
