//! The `schrl` binary links MuJoCo when built with `--features mujoco`: the same
//! rpath as the sim crate's own binaries (see that build script).
include!("../sim/build.rs");
