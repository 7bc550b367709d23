//! One module per subcommand.

pub mod control;
pub mod plan;
pub mod robustness;
pub mod sim;
pub mod spec_text;
pub mod task;
