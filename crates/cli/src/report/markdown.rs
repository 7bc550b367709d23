//! The report as markdown: the tables the README shows, pasted from here.

use super::{Section, provenance};

/// One table in GitHub markdown.
pub fn table(headings: &[String], rows: &[Vec<String>]) -> String {
    let line = |cells: &[String]| {
        format!("| {} |\n", cells.iter().map(|c| c.replace('|', "\\|")).collect::<Vec<_>>().join(" | "))
    };
    let mut out = line(headings);
    out += &format!("|{}\n", "---|".repeat(headings.len()));
    for row in rows {
        out += &line(row);
    }
    out
}

/// The whole report: a section per experiment with its table and pictures.
pub fn report(sections: &[Section]) -> String {
    let mut out =
        String::from("# schrl results\n\nWritten by `schrl report` from the experiments' `results.jsonl`.\n");
    for s in sections {
        let t = &s.table;
        out += &format!("\n## {}\n\n{}\n\n", t.experiment.title(), provenance(s));
        out += &table(&t.headings, &t.rows);
        for p in &s.pictures {
            out += &format!("\n![{}]({})\n", p.caption, p.path);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn tables_escape_pipes_and_have_one_rule() {
        let t = super::table(&["a".into(), "b".into()], &[vec!["1".into(), "x|y".into()]]);
        assert_eq!(t, "| a | b |\n|---|---|\n| 1 | x\\|y |\n");
    }
}
