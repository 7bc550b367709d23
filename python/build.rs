//! With `--features mujoco` the extension module links MuJoCo: the same rpath as the sim
//! crate's own binaries, so `import schrl` finds `libmujoco.so` without
//! `LD_LIBRARY_PATH`.

include!("../crates/sim/mujoco_rpath.rs");

fn main() {
    mujoco_rpath();
}
