//! `schrl sim render` end to end.

use std::process::Command;

fn schrl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).args(args).output().expect("runs")
}

#[test]
fn renders_each_robot_with_a_rollout() {
    let dir = std::env::temp_dir().join(format!("schrl-sim-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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
