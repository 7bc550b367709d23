//! `schrl sim render` end to end.

use std::process::Command;

fn schrl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).args(args).output().expect("runs")
}

#[test]
fn renders_each_robot_with_a_rollout() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    for robot in ["point", "car", "drone"] {
        let out = dir.join(format!("{robot}.png"));
        let _ = std::fs::remove_file(&out);
        let o =
            schrl(&["sim", "render", "--robot", robot, "--out", out.to_str().unwrap(), "--rollout", "300"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(std::fs::metadata(&out).unwrap().len() > 1000);
        // A second run must not replace it silently.
        let o = schrl(&["sim", "render", "--robot", robot, "--out", out.to_str().unwrap()]);
        assert!(!o.status.success());
        assert!(String::from_utf8_lossy(&o.stderr).contains("--force"));
    }
}

#[test]
fn unknown_robot_or_map_is_a_clear_error() {
    let o = schrl(&["sim", "render", "--robot", "tank", "--out", "x.png"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown robot 'tank'"));
    let o = schrl(&["sim", "render", "--robot", "point", "--map", "maze", "--out", "x.png"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown map 'maze'"));
    let o = schrl(&["sim", "render", "--robot", "drone", "--map", "walls", "--out", "x.png"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("needs a 3-D map"));
}

/// Without the `mujoco` feature the Doggo is refused with the way to enable it; with
/// it, the Doggo renders like the other robots.
#[test]
fn doggo_renders_with_mujoco_and_says_how_to_enable_it_without() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let out = dir.join("doggo.png");
    let _ = std::fs::remove_file(&out);
    let o = schrl(&["sim", "render", "--robot", "doggo", "--out", out.to_str().unwrap(), "--rollout", "200"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    if cfg!(feature = "mujoco") {
        assert!(o.status.success(), "{stderr}");
        assert!(std::fs::metadata(&out).unwrap().len() > 1000);
    } else {
        assert!(!o.status.success());
        assert!(
            stderr.contains("scripts/setup-mujoco.sh") && stderr.contains("--features mujoco"),
            "{stderr}"
        );
    }
}
