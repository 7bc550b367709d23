// The rpath of MuJoCo for this package's binaries (see the included file).
include!("mujoco_rpath.rs");

fn main() {
    mujoco_rpath();
}
