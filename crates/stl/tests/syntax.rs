//! The text syntax: printing round-trips, errors are located, no input panics.

mod common;

use proptest::prelude::*;
use stl::{Formula, parse};

proptest! {
    #![proptest_config(ProptestConfig { cases: 1024, ..ProptestConfig::default() })]

    /// parse(print(f)) == f.
    #[test]
    fn print_then_parse_round_trips(f in common::formula()) {
        let text = f.to_string();
        let back = parse(&text).map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
        prop_assert_eq!(back, f, "{}", text);
    }

    /// Arbitrary text never panics the parser.
    #[test]
    fn arbitrary_text_never_panics(s in "\\PC{0,60}") {
        let _ = parse(&s);
    }

    /// Nor does text made of the syntax's own tokens, which reaches deeper.
    #[test]
    fn token_soup_never_panics(toks in prop::collection::vec(prop::sample::select(vec![
        "(", ")", "[", "]", ",", "!", "&", "|", "->", "=>", "X", "F", "G", "U", "true", "false", "inf",
        "a", "x", ">", ">=", "<", "<=", "0", "3", "-1.5", "1e9", "99999999999999999999", "\n", "#c\n",
    ]), 0..40)) {
        let s = toks.join(" ");
        if let Err(e) = parse(&s) {
            prop_assert!(e.line >= 1 && e.column >= 1);
            let _ = e.render(&s);
        }
    }
}

#[test]
fn accepts_every_required_form() {
    for src in [
        "true",
        "false",
        "!a",
        "a & b",
        "a | b",
        "a -> b",
        "X a",
        "F[1,2] a",
        "G[0,3] a",
        "a U[1,4] b",
        "F a",
        "G a",
        "(a)",
        "x > 0.5",
        "x >= 0.5",
        "x < 0.5",
        "x <= 0.5",
        "x > -1e-3",
        "F[2,inf] a",
        "a && b || c => d",
        "# comment\nF a # trailing",
    ] {
        parse(src).unwrap_or_else(|e| panic!("{src}: {e}"));
    }
}

#[test]
fn error_messages_say_what_was_expected() {
    let cases = [
        ("", 1, 1, "a formula"),
        ("a &", 1, 4, "a formula"),
        ("F[1 2] a", 1, 5, "','"),
        ("F[1,2 a", 1, 7, "']'"),
        ("F[1.5,2] a", 1, 3, "whole number"),
        ("F[a,2] b", 1, 3, "interval's start"),
        ("(a | b", 1, 7, "')'"),
        ("a b", 1, 3, "an operator"),
        ("x > y", 1, 5, "a number after 'x >'"),
        ("G[4,2] a", 1, 5, "interval end >= its start 4"),
        ("F[0,99999999999] a", 1, 5, "at most"),
        ("U", 1, 1, "a formula"),
    ];
    for (src, line, column, expected) in cases {
        let e = parse(src).expect_err(src);
        assert_eq!((e.line, e.column), (line, column), "{src}: {e}");
        assert!(e.expected.contains(expected), "{src}: {e}");
    }
}

#[test]
fn printer_uses_the_fewest_parentheses() {
    let a = || Formula::atom("a");
    let b = || Formula::atom("b");
    assert_eq!((a() & b()).implies(a() | b()).to_string(), "a & b -> a | b");
    assert_eq!(Formula::And(vec![Formula::Or(vec![a(), b()]), a()]).to_string(), "(a | b) & a");
    assert_eq!((!(a() & b())).eventually(1, 2).to_string(), "F[1,2] !(a & b)");
    assert_eq!(a().until(0, 3, b()).globally_from(1).to_string(), "G[1,inf] (a U[0,3] b)");
    assert_eq!(a().implies(b()).implies(a()).to_string(), "(a -> b) -> a");
}

#[test]
fn builder_matches_the_issue_example() {
    let reach = |n: &str| Formula::atom(n);
    let f = reach("goal").eventually(1, 2) & reach("safe").globally(1, 8);
    assert_eq!(f, parse("F[1,2] goal & G[1,8] safe").unwrap());
    assert_eq!(f.horizon(), Some(8));
    assert_eq!(f.names(), vec!["goal", "safe"]);
}

/// Regression: `until` reads its left operand only before the step where the right
/// one holds (App. C), so `(X a) U[1,3] b` looks 3 steps ahead, not 4; the Signal
/// task's spec spans exactly its 12 waypoints.
#[test]
fn until_horizon_counts_the_left_operand_one_step_short() {
    assert_eq!(parse("(X a) U[1,3] b").unwrap().horizon(), Some(3));
    assert_eq!(parse("(X X a) U[1,3] b").unwrap().horizon(), Some(4));
    assert_eq!(parse("a U[1,3] (X b)").unwrap().horizon(), Some(4));
    assert_eq!(parse("(X a) U[2,2] b").unwrap().horizon(), Some(2));
    assert_eq!(parse("a U[1,3] b").unwrap().horizon(), Some(3));
}

/// Pre-training's horizon curriculum: windows that read to the last waypoint end
/// earlier on a shorter path; fixed-time windows, nested ones and empty results have
/// no shorter form.
#[test]
fn end_anchored_prefix_shortens_windows_that_reach_the_end() {
    let loop_spec = "(G[1,17] (l0 | l1) & G[1,16] ((l0 -> !X l0) & (l1 -> !X l1))) & G[1,17] safe";
    let cut = parse(loop_spec).unwrap().end_anchored_prefix(17, 4).unwrap();
    assert_eq!(
        cut,
        parse("(G[1,4] (l0 | l1) & G[1,3] ((l0 -> !X l0) & (l1 -> !X l1))) & G[1,4] safe").unwrap()
    );
    assert_eq!(cut.horizon(), Some(4));
    assert_eq!(parse(loop_spec).unwrap().end_anchored_prefix(17, 17), Some(parse(loop_spec).unwrap()));
    assert_eq!(parse("a U[1,12] b").unwrap().end_anchored_prefix(12, 5), Some(parse("a U[1,5] b").unwrap()));
    // Seq's first goal is due at waypoints 1–2 whatever the path's length.
    assert_eq!(parse("F[1,2] g0 & F[7,8] g3 & G[1,8] safe").unwrap().end_anchored_prefix(8, 4), None);
    assert_eq!(parse("G[1,8] F[0,2] a").unwrap().end_anchored_prefix(10, 4), None);
    assert_eq!(parse("G[6,8] a").unwrap().end_anchored_prefix(8, 4), None, "empty window");
    assert_eq!(parse("G[1,inf] a").unwrap().end_anchored_prefix(8, 4), None);
    assert_eq!(parse("G[1,4] a").unwrap().end_anchored_prefix(4, 5), None);
}
