//! The report as one static HTML page: no server, no external resources; pictures are
//! files beside it.

use super::{Section, provenance};

/// Text as HTML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Counts, once the page has loaded, its tables with rows and the pictures that decoded, into
/// `data-tables` and `data-images` on `<body>` (`"3 of 3"`): what the page test reads.
const CHECK: &str = r#"<script>
window.addEventListener("load", () => {
  const images = [...document.images];
  const shown = images.filter((i) => i.complete && i.naturalWidth > 0).length;
  const filled = [...document.querySelectorAll("table")].filter((t) => t.tBodies[0]?.rows.length > 0);
  document.body.dataset.tables = String(filled.length);
  document.body.dataset.images = `${shown} of ${images.length}`;
});
</script>"#;

const STYLE: &str = "body{font-family:sans-serif;max-width:72rem;margin:2rem auto;padding:0 1rem}\
table{border-collapse:collapse;margin:1rem 0}th,td{border:1px solid #bbb;padding:.25rem .5rem;text-align:right}\
th{background:#eee}td:nth-child(-n+3),th:nth-child(-n+3){text-align:left}figure{display:inline-block;margin:.5rem}\
figure img{max-width:34rem;border:1px solid #ddd}figcaption{font-size:.85rem;color:#444}";

/// The page.
pub fn page(sections: &[Section]) -> String {
    let mut out = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>schrl results</title>\n\
         <style>{STYLE}</style>\n</head>\n<body>\n<h1>schrl results</h1>\n\
         <p>Written by <code>schrl report</code> from the experiments' <code>results.jsonl</code>.</p>\n"
    );
    for s in sections {
        let t = &s.table;
        out += &format!(
            "<section id=\"{}\">\n<h2>{}</h2>\n<p>{}</p>\n<table>\n<thead><tr>",
            t.experiment.name(),
            escape(t.experiment.title()),
            escape(&provenance(s))
        );
        for h in &t.headings {
            out += &format!("<th>{}</th>", escape(h));
        }
        out += "</tr></thead>\n<tbody>\n";
        for row in &t.rows {
            out += "<tr>";
            for c in row {
                out += &format!("<td>{}</td>", escape(c));
            }
            out += "</tr>\n";
        }
        out += "</tbody>\n</table>\n";
        for p in &s.pictures {
            out += &format!(
                "<figure><img src=\"{}\" alt=\"{}\" loading=\"eager\"><figcaption>{}</figcaption></figure>\n",
                escape(&p.path),
                escape(&p.caption),
                escape(&p.caption)
            );
        }
        out += "</section>\n";
    }
    out += CHECK;
    out += "\n</body>\n</html>\n";
    out
}
