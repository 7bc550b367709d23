//! Records the git commit the binary is built from, for the results it writes
//! (`schrl experiment` records name it): `SCHRL_GIT_COMMIT`, absent outside a checkout,
//! with `-dirty` appended when tracked files differ from it (the build then holds
//! code no commit names).
//! With `--features mujoco` the binary links MuJoCo: the same rpath as the sim crate's
//! own binaries.

include!("../sim/mujoco_rpath.rs");

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    mujoco_rpath();
    println!("cargo:rerun-if-changed=build.rs");
    let Some(git_dir) = git(&["rev-parse", "--absolute-git-dir"]) else { return };
    // A new commit moves HEAD or the branch it names.
    // (A missing path would rerun this script on every build.)
    for path in ["HEAD", "refs/heads", "packed-refs"] {
        let path = format!("{git_dir}/{path}");
        if std::path::Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    // Editing or staging tracked files changes whether the tree is dirty; the
    // workspace's sources are what a binary is built from.
    println!("cargo:rerun-if-changed={git_dir}/index");
    for path in ["../../crates", "../../Cargo.toml", "../../Cargo.lock"] {
        println!("cargo:rerun-if-changed={path}");
    }
    if let Some(commit) = git(&["rev-parse", "HEAD"]) {
        let dirty = git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
        let suffix = if dirty { "-dirty" } else { "" };
        println!("cargo:rustc-env=SCHRL_GIT_COMMIT={commit}{suffix}");
    }
}
