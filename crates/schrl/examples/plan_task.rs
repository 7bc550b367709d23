//! Trains the GRU-ODE planner on one Point task with the constrained policy
//! gradient until 95% of sampled paths satisfy the spec.
//!
//! Run: `cargo run --release -p schrl --example plan_task -- seq [seed] [cpg|pg] [hard|soft:<α>|lse:<τ>]`

use std::time::Instant;

use schrl::plan::cpg::{CpgConfig, Method, PlanTrainer};
use schrl::task::{Task, TaskKind};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let kind: TaskKind = args.get(1).map_or("seq", |s| s.as_str()).parse()?;
    let seed: u64 = args.get(2).map_or(Ok(0), |s| s.parse())?;
    let method = if args.get(3).map(|s| s.as_str()) == Some("pg") { Method::Pg } else { Method::Cpg };
    let semantics = match args.get(4) {
        Some(s) => s.parse()?,
        None => CpgConfig::default().semantics,
    };
    let cfg = CpgConfig { seed, method, semantics, ..CpgConfig::default() };
    let mut trainer = PlanTrainer::new(Task::point(kind), cfg)?;
    let start = Instant::now();
    for update in 1..=3000 {
        let s = trainer.update()?;
        if update % 50 == 0 || s.satisfaction >= 0.95 {
            println!(
                "update {update:5}: satisfaction {:.2}  mean ρ {:+.3}  λ {:.3}  ({:.2} ms/update)",
                s.satisfaction,
                s.mean_rho,
                s.lambda,
                start.elapsed().as_secs_f64() * 1e3 / update as f64
            );
        }
        if s.satisfaction >= 0.95 && trainer.satisfaction(200)? >= 0.95 {
            println!("reached 95% after {update} updates");
            return Ok(());
        }
    }
    println!("did not reach 95%");
    Ok(())
}
