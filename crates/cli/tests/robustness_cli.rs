//! `schrl robustness` end to end: output format and error handling.

use std::path::PathBuf;
use std::process::{Command, Output};

fn schrl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).args(args).output().expect("runs")
}

/// Writes `text` to `dir/name` (each test's own scratch directory, removed when it ends).
fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn last_line(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).lines().last().unwrap_or("").to_string()
}

#[test]
fn prints_robustness_as_the_last_line() {
    let dir = tempfile::tempdir().unwrap();
    let trace = write(&dir, "ok.csv", "x,y\n0,0\n1,0.5\n2,1\n");
    let t = trace.to_str().unwrap();
    let o = schrl(&["robustness", "--spec", "F[1,2] x > 1.5 & G y >= -1", "--trace", t]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(last_line(&o), "0.5");
    let spec = write(&dir, "spec.stl", "# reach x > 1.5\nF x > 1.5\n");
    let at = format!("@{}", spec.display());
    let o = schrl(&["robustness", "--spec", &at, "--trace", t, "--semantics", "lse:0.01"]);
    let v: f64 = last_line(&o).parse().unwrap();
    assert!((v - 0.5).abs() < 0.02, "{v}");
    let o = schrl(&["robustness", "--spec", "F x > 1.5", "--trace", t, "--semantics", "soft:2"]);
    let v: f64 = last_line(&o).parse().unwrap();
    assert!(v < 0.5 && v > -1.5, "soft max lies between min and max: {v}");
}

#[test]
fn writes_the_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let trace = write(&dir, "g.csv", "x,y\n0,0\n3,0\n1,0\n");
    let grad = trace.with_file_name("grad.csv");
    let o = schrl(&[
        "robustness",
        "--spec",
        "F x > 1",
        "--trace",
        trace.to_str().unwrap(),
        "--gradient",
        grad.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    assert_eq!(std::fs::read_to_string(grad).unwrap(), "x,y\n0,0\n1,0\n0,0\n");
}

fn fails_with(args: &[&str], needle: &str) {
    let o = schrl(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "should fail: {args:?}");
    assert!(err.contains(needle), "stderr lacks '{needle}':\n{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let ok = write(&dir, "ok2.csv", "x,y\n0,0\n1,1\n");
    let ok = ok.to_str().unwrap();
    fails_with(
        &["robustness", "--spec", "F[1,2] (x > 1 &", "--trace", ok],
        "line 1, column 16: expected a formula",
    );
    fails_with(&["robustness", "--spec", "F goal", "--trace", ok], "line 1, column 3: 'goal' is not bound");
    fails_with(
        &["robustness", "--spec", "F x > 1", "--trace", ok, "--semantics", "soft:-1"],
        "alpha must be",
    );
    fails_with(
        &["robustness", "--spec", "F x > 1", "--trace", ok, "--semantics", "fuzzy"],
        "unknown semantics",
    );
    let ragged = write(&dir, "ragged.csv", "x,y\n1,2\n3\n");
    fails_with(
        &["robustness", "--spec", "F x > 1", "--trace", ragged.to_str().unwrap()],
        "line 3: 1 fields, but the header has 2",
    );
    let nonnum = write(&dir, "nonnum.csv", "x,y\n1,2\n3,abc\n");
    fails_with(
        &["robustness", "--spec", "F x > 1", "--trace", nonnum.to_str().unwrap()],
        "line 3, column 'y': 'abc' is not a finite number",
    );
    let empty = write(&dir, "empty.csv", "x,y\n");
    fails_with(&["robustness", "--spec", "F x > 1", "--trace", empty.to_str().unwrap()], "no rows");
    let badname = write(&dir, "badname.csv", "x,my y\n1,2\n");
    fails_with(
        &["robustness", "--spec", "F x > 1", "--trace", badname.to_str().unwrap()],
        "not a valid signal name",
    );
    fails_with(&["robustness", "--spec", "F x > 1", "--trace", "/nonexistent/t.csv"], "cannot read trace");
    fails_with(&["robustness", "--spec", "@/nonexistent/s.stl", "--trace", ok], "cannot read spec file");
}

#[test]
fn inputs_without_end_starts_past_the_end_and_overwriting_the_input_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let ok = write(&dir, "ok3.csv", "x,y\n0,0\n1,1\n");
    let ok = ok.to_str().unwrap();
    // Regression: these read until memory ran out.
    fails_with(&["robustness", "--spec", "@/dev/zero", "--trace", ok], "larger than 1024 KiB");
    fails_with(&["robustness", "--spec", "F x > 0", "--trace", "/dev/zero"], "larger than");
    // Regression: --at past the end answered the last step's value.
    fails_with(
        &["robustness", "--spec", "x > 0", "--trace", ok, "--at", "2"],
        "--at 2: the trace has 2 rows",
    );
    assert_eq!(last_line(&schrl(&["robustness", "--spec", "x > 0", "--trace", ok, "--at", "1"])), "1");
    // Regression: --gradient onto the trace overwrote the input.
    fails_with(&["robustness", "--spec", "F x > 0", "--trace", ok, "--gradient", ok], "is the trace itself");
    assert_eq!(std::fs::read_to_string(ok).unwrap(), "x,y\n0,0\n1,1\n");
    let grad = write(&dir, "kept.csv", "precious");
    let g = grad.to_str().unwrap();
    fails_with(&["robustness", "--spec", "F x > 0", "--trace", ok, "--gradient", g], "--force");
    assert_eq!(std::fs::read_to_string(&grad).unwrap(), "precious");
    assert!(
        schrl(&["robustness", "--spec", "F x > 0", "--trace", ok, "--gradient", g, "--force"])
            .status
            .success()
    );
    // `true` is +∞ in STL, not the library's finite stand-in.
    assert_eq!(last_line(&schrl(&["robustness", "--spec", "true", "--trace", ok])), "inf");
    assert_eq!(last_line(&schrl(&["robustness", "--spec", "false | x > 5", "--trace", ok])), "-5");
    // Until: standard by default (φ from t), the paper's reading (φ from t+a) on request.
    let tr = write(&dir, "until.csv", "x\n-1\n2\n3\n7\n");
    let until = |rule: &str| {
        last_line(&schrl(&[
            "robustness",
            "--spec",
            "x > 0 U[1,3] x > 5",
            "--trace",
            tr.to_str().unwrap(),
            "--until",
            rule,
        ]))
    };
    assert_eq!((until("standard"), until("paper")), ("-1".to_string(), "2".to_string()));
    // A byte-order mark before the spec is not a syntax error.
    let bom = write(&dir, "bom.stl", "\u{feff}F x > 0\n");
    let spec = format!("@{}", bom.display());
    assert_eq!(last_line(&schrl(&["robustness", "--spec", &spec, "--trace", ok])), "1");
}

/// The smooth `until` relaxations are chosen in the semantics text; hard has none.
#[test]
fn until_relaxation_is_named_and_hard_refuses_one() {
    let dir = tempfile::tempdir().unwrap();
    let trace = write(&dir, "u.csv", "x,y\n1,0\n1,0\n1,2\n");
    let t = trace.to_str().unwrap();
    let value = |sem: &str| -> f64 {
        let o = schrl(&["robustness", "--spec", "x > 0 U y > 1", "--trace", t, "--semantics", sem]);
        assert!(o.status.success(), "{sem}: {}", String::from_utf8_lossy(&o.stderr));
        last_line(&o).parse().unwrap()
    };
    let (rec, flat) = (value("lse:0.5"), value("lse:0.5,until=flat"));
    assert_eq!(rec, value("lse:0.5,until=recursive"));
    assert!((rec - flat).abs() > 1e-6, "two relaxations: {rec} {flat}");
    let o = schrl(&["robustness", "--spec", "x > 0 U y > 1", "--trace", t, "--semantics", "hard,until=flat"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("hard semantics has no until relaxation"));
}
