// With the `mujoco` feature, records MuJoCo's folder (`MUJOCO_DYNAMIC_LINK_DIR`,
// set by `.cargo/config.toml` to where `scripts/setup-mujoco.sh` installs it) as an
// rpath of this package's binaries (tests, benches, examples), so that they find
// `libmujoco.so.3.17.0` without `LD_LIBRARY_PATH`. Packages that link MuJoCo into
// their own binaries include this file from their build script and call
// `mujoco_rpath`.

/// Records MuJoCo's folder as an rpath when the `mujoco` feature is on.
fn mujoco_rpath() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    println!("cargo::rerun-if-env-changed=CARGO_FEATURE_MUJOCO");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_none() {
        return;
    }
    if let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR") {
        let dir = dir.to_string_lossy();
        if std::env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("windows") {
            println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
        }
    }
}
