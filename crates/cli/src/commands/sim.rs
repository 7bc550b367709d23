//! `schrl sim`: look at the simulated robots and maps.

use std::path::PathBuf;

use anyhow::{Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sim::render::{Goal, PathKind, Polyline, RobotMarker, Scene};
use sim::{EnvError, Map, Robot, make_env};

/// Subcommands of `schrl sim`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Draw a map with a robot (and optionally a random-action rollout) to PNG or SVG.
    Render(RenderArgs),
}

/// Arguments of `schrl sim render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Robot: point, car, drone, or doggo (needs the `mujoco` feature).
    #[arg(long, value_parser = parse_robot)]
    robot: Robot,
    /// Map: walls, empty or duck (default: walls for ground robots, duck for the drone).
    #[arg(long, value_parser = parse_map)]
    map: Option<Map>,
    /// Output picture (.png or .svg).
    #[arg(long)]
    out: PathBuf,
    /// Draw the trajectory of this many random-action steps.
    #[arg(long, default_value_t = 0, value_parser = super::count::<0, 1_000_000>)]
    rollout: usize,
    /// Seed of the start, goal and random actions.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Replace the output if it exists.
    #[arg(long)]
    force: bool,
}

fn parse_robot(s: &str) -> Result<Robot, String> {
    s.parse().map_err(|e: EnvError| e.to_string())
}

fn parse_map(s: &str) -> Result<Map, String> {
    Map::by_name(s).ok_or_else(|| EnvError::UnknownMap(s.to_string()).to_string())
}

/// Runs `schrl sim ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Render(args) => render(args),
    }
}

fn render(args: RenderArgs) -> Result<()> {
    let map = args.map.unwrap_or_else(|| args.robot.default_map());
    let mut env = make_env(args.robot, map.clone())?;
    env.reset(args.seed, None)?;
    let mut scene = Scene::new(map);
    scene.goals.push(Goal { center: env.goal().to_vec(), radius: env.reach_radius(), avoid: false });
    let mut trail = vec![env.position().to_vec()];
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed ^ 0x5EED);
    let dim = env.action_space().dim();
    let mut action = vec![0.0; dim];
    let mut collisions = 0;
    for t in 0..args.rollout {
        // Hold each random action for 20 steps so the robot travels visibly.
        if t % 20 == 0 {
            action.iter_mut().for_each(|a| *a = rng.random_range(-1.0..1.0));
        }
        let (_, step) = env.step(&action)?;
        collisions += step.collided as usize;
        trail.push(env.position().to_vec());
    }
    if args.rollout > 0 {
        scene.paths.push(Polyline { points: trail, kind: PathKind::Executed });
    }
    scene.robots.push(RobotMarker {
        position: env.position().to_vec(),
        heading: env.heading(),
        radius: env.radius(),
    });
    sim::render::save(&scene, &args.out, args.force)
        .with_context(|| "cannot render the scene".to_string())?;
    println!(
        "wrote {} ({} on {}, {} steps, {} with contact)",
        args.out.display(),
        args.robot,
        scene.map.name(),
        args.rollout,
        collisions
    );
    Ok(())
}
