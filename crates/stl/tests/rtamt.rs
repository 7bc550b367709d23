//! The standard until against rtamt 0.4.10 (discrete time, offline), on values
//! computed once by `scripts/rtamt-fixtures.py` and stored in `tests/fixtures`.

use stl::{Semantics, Spec, UntilRule, parse};

const TRACE: &str = include_str!("fixtures/rtamt_trace.csv");
const EXPECTED: &str = include_str!("fixtures/rtamt_expected.csv");

fn trace() -> Vec<f64> {
    TRACE.lines().skip(1).flat_map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap())).collect()
}

/// `(formula, t, robustness)` rows.
fn expected() -> Vec<(String, usize, f64)> {
    EXPECTED
        .lines()
        .skip(1)
        .map(|l| {
            let (formula, rest) = l.strip_prefix('"').unwrap().split_once("\",").unwrap();
            let (t, v) = rest.split_once(',').unwrap();
            (formula.to_string(), t.parse().unwrap(), v.parse().unwrap())
        })
        .collect()
}

fn signal(formula: &str, rule: UntilRule) -> Vec<f64> {
    let spec = Spec::builder(parse(formula).unwrap()).until(rule).signals(["x", "y"]).build().unwrap();
    spec.robustness_signal(&trace(), &Semantics::hard()).unwrap()
}

#[test]
fn the_standard_until_matches_rtamt() {
    let rows = expected();
    assert!(rows.len() > 300);
    for (formula, t, want) in &rows {
        let got = signal(formula, UntilRule::Standard)[*t];
        assert!((got - want).abs() < 1e-9, "{formula} at {t}: schrl {got}, rtamt {want}");
    }
}

#[test]
fn the_papers_until_differs_from_rtamt_where_the_window_starts_late() {
    // The example: `(x>0) U[3,20] (y>1)` read as App. C asks less of φ.
    let rows = expected();
    let late: Vec<_> = rows.iter().filter(|(f, _, _)| f.starts_with("x > 0 U[3,20]")).collect();
    let differ =
        late.iter().filter(|(f, t, want)| (signal(f, UntilRule::Paper)[*t] - want).abs() > 1e-9).count();
    assert!(differ > 0, "no start step tells the two readings apart");
    // A window starting at 0 reads the same either way.
    for (f, t, want) in rows.iter().filter(|(f, _, _)| f.starts_with("x > 0 U[0,5]")) {
        assert!((signal(f, UntilRule::Paper)[*t] - want).abs() < 1e-9);
    }
}
