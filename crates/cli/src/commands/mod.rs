//! One module per subcommand.

pub mod robustness;
pub mod spec_text;
