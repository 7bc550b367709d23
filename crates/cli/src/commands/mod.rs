//! One module per subcommand.

pub mod robustness;
pub mod sim;
pub mod spec_text;
