//! Task files as a hostile user might write them: whatever the TOML and the spec
//! say, loading gives a task or an error naming the file, never a panic, and a task
//! that loads can be bound and evaluated. A bounded number of cases, so CI stays fast.

use std::path::Path;

use proptest::prelude::*;
use schrl::task::Task;

const TOML: &str = include_str!("../../../examples/tasks/keys.toml");
const SPEC: &str = include_str!("../../../examples/tasks/keys.stl");

/// Numbers that break naive code: zero, negatives, huge, not finite.
fn nasty_number() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("0".to_string()),
        Just("-1".to_string()),
        Just("1e308".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("18446744073709551615".to_string()),
        Just("1000000".to_string()),
        (-1e4f64..1e4).prop_map(|x| x.to_string()),
        (0usize..3000).prop_map(|x| x.to_string()),
    ]
}

/// The keys task's TOML with one number replaced, one line dropped or duplicated.
fn mutated_toml() -> impl Strategy<Value = String> {
    let lines: Vec<String> = TOML.lines().map(str::to_string).collect();
    let n = lines.len();
    (0..n, nasty_number(), 0..3u8).prop_map(move |(at, number, how)| {
        let mut out = lines.clone();
        match how {
            0 => {
                // Replace the first number on the line.
                let l = &out[at];
                if let Some(start) = l.find(|c: char| c.is_ascii_digit() || c == '-') {
                    let end = l[start..]
                        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
                        .map_or(l.len(), |e| start + e);
                    out[at] = format!("{}{}{}", &l[..start], number, &l[end..]);
                }
            }
            1 => {
                out.remove(at);
            }
            _ => out.insert(at, out[at].clone()),
        }
        out.join("\n")
    })
}

/// Spec text from the spec language's own pieces and the task's names.
fn spec_text() -> impl Strategy<Value = String> {
    let pieces = [
        "F", "G", "X", "U", "!", "&", "|", "->", "(", ")", "[1,2]", "[0,6]", "[3,1]", "[0,inf]", "[1,7]",
        "key_a", "key_b", "home", "hazard", "safe", "true", "false", "counter", "x", ">", "0.5", "nan",
        "\u{feff}", "#c\n", "\n",
    ];
    proptest::collection::vec(proptest::sample::select(pieces.to_vec()), 0..24).prop_map(|v| v.join(" "))
}

fn check(toml: &str, spec: &str) -> Result<(), TestCaseError> {
    match Task::from_texts(Path::new("t.toml"), toml, Path::new("t.stl"), spec) {
        Err(e) => {
            let shown = e.to_string();
            prop_assert!(shown.starts_with("t.toml: ") || shown.starts_with("t.stl: "), "{}", shown);
        }
        Ok(task) => {
            let path = vec![0.5; (task.steps + 1) * task.map.dim()];
            let rho = task.spec().robustness(&path, &stl::Semantics::hard());
            prop_assert!(rho.is_ok(), "{:?}", rho);
            let reached_at: Vec<usize> = (1..=task.steps).collect();
            let executed: Vec<Vec<f64>> = path.chunks(task.map.dim()).map(|c| c.to_vec()).collect();
            task.execution_spec().judge(&executed, &executed, &reached_at);
            let _ = task.warnings();
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn mutated_task_files_load_or_fail_cleanly(toml in mutated_toml()) {
        check(&toml, SPEC)?;
    }

    #[test]
    fn arbitrary_specs_load_or_fail_cleanly(spec in spec_text()) {
        check(TOML, &spec)?;
    }

    #[test]
    fn arbitrary_text_as_a_task_file_fails_cleanly(toml in "\\PC{0,200}") {
        check(&toml, SPEC)?;
    }
}
