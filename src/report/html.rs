//! `idrex report --format html`: the report as one self-contained page. It renders the same
//! text as `report.md` (headings, paragraphs, tables, figures, links: the subset the report
//! writes), with every table sortable by a click on its header, every figure inlined (SVG as
//! markup, PNG as a data URI), the per-table details and the clone table folded away, and
//! links to the rollouts' MCAP files and the Rerun recordings. Nothing loads from outside the
//! page: no script, style sheet, font or image is fetched.
use std::fmt::Write as _;
use std::path::Path;

use crate::log::table::escape;

/// Sections whose title starts with one of these open folded: per-table detail.
const FOLDED: [&str; 4] = ["Ground-truth return", "Learned reward on the policies", "Three protocols", "Multi-BC clones"];

const STYLE: &str = "body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:1em 0;font-size:13px}th,td{border:1px solid #ccc;padding:3px 6px;text-align:left}\
th{background:#f0f0f0;cursor:pointer;user-select:none}th:hover{background:#e0e8f0}\
tr:nth-child(even) td{background:#fafafa}details{margin:1em 0}summary{cursor:pointer;font-weight:bold;font-size:1.2em}\
figure{margin:1em 0}figure svg,figure img{max-width:100%;height:auto}code{background:#f4f4f4;padding:0 3px}";

/// Click a header to sort by it; numbers (a cell's leading number) sort as numbers.
const SCRIPT: &str = "document.querySelectorAll('table.sortable th').forEach(function(th,i){th.addEventListener('click',function(){\
var t=th.closest('table'),b=t.tBodies[0],rows=Array.from(b.rows),asc=th.dataset.asc!=='1';\
t.querySelectorAll('th').forEach(function(h){h.dataset.asc=''});th.dataset.asc=asc?'1':'0';\
var key=function(r){var c=r.cells[i];var v=c?c.textContent.trim():'';var n=parseFloat(v);return isNaN(n)?v:n};\
rows.sort(function(a,b){var x=key(a),y=key(b);var c=(typeof x==='number'&&typeof y==='number')?x-y:String(x).localeCompare(String(y));\
return asc?c:-c});rows.forEach(function(r){b.appendChild(r)})})});";

/// Inline markdown: code spans, bold, links.
fn inline(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix('`')
            && let Some(end) = r.find('`')
        {
            let _ = write!(out, "<code>{}</code>", escape(&r[..end]));
            rest = &r[end + 1..];
        } else if let Some(r) = rest.strip_prefix("**")
            && let Some(end) = r.find("**")
        {
            let _ = write!(out, "<b>{}</b>", inline(&r[..end]));
            rest = &r[end + 2..];
        } else if let Some(r) = rest.strip_prefix('[')
            && let Some(mid) = r.find("](")
            && let Some(end) = r[mid..].find(')')
        {
            let (label, href) = (&r[..mid], &r[mid + 2..mid + end]);
            let _ = write!(out, "<a href=\"{}\">{}</a>", escape(href), inline(label));
            rest = &r[mid + end + 1..];
        } else {
            let c = rest.chars().next().expect("not empty");
            out.push_str(&escape(&c.to_string()));
            rest = &rest[c.len_utf8()..];
        }
    }
    out
}

fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    // `\|` is a bar inside a cell.
    inner.replace("\\|", "\u{0}").split('|').map(|c| c.trim().replace('\u{0}', "|")).collect()
}

fn table(lines: &[&str]) -> String {
    let mut out = String::from("<table class=\"sortable\"><thead><tr>");
    for c in cells(lines[0]) {
        let _ = write!(out, "<th>{}</th>", inline(&c));
    }
    out.push_str("</tr></thead><tbody>\n");
    for l in lines.iter().skip(2) {
        out.push_str("<tr>");
        for c in cells(l) {
            let _ = write!(out, "<td>{}</td>", inline(&c));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</tbody></table>\n");
    out
}

/// A figure from `dir`: SVG inlined as markup, PNG as a data URI.
fn figure(alt: &str, path: &str, dir: &Path) -> String {
    let file = dir.join(path);
    let body = if path.ends_with(".svg") {
        std::fs::read_to_string(&file).ok().map(|s| {
            let start = s.find("<svg").unwrap_or(0);
            s[start..].to_string()
        })
    } else {
        std::fs::read(&file).ok().map(|b| format!("<img alt=\"{}\" src=\"data:image/png;base64,{}\">", escape(alt), base64(&b)))
    };
    match body {
        // The report puts the title in the line above.
        Some(b) => format!("<figure>{b}</figure>\n"),
        None => format!("<p>(figure {} is missing)</p>\n", escape(path)),
    }
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let n = chunk.iter().enumerate().fold(0u32, |n, (i, &b)| n | u32::from(b) << (16 - 8 * i));
        for i in 0..4 {
            out.push(if i <= chunk.len() { A[(n >> (18 - 6 * i) & 63) as usize] as char } else { '=' });
        }
    }
    out
}

/// What the page links to besides its own content.
#[derive(Debug, Clone, Default)]
pub struct Links {
    /// (label, location) of each evaluation's rollouts.
    pub rollouts: Vec<(String, String)>,
    /// Rerun recordings (`.rrd`).
    pub recordings: Vec<String>,
}

/// Each evaluation's rollouts in a local store, labelled by its table cell (a bucket's
/// objects are named by digest, so there is no file to link to; an archived result has none
/// on this machine).
pub fn rollout_links(artifacts: &super::Artifacts, store: Option<&crate::store::Store>) -> Vec<(String, String)> {
    let Some(store) = store.filter(|s| s.url().is_none()) else { return Vec::new() };
    let mut out: Vec<(String, String)> = artifacts
        .evaluations()
        .filter(|(m, _, _)| !artifacts.is_archived(&m.key))
        .filter_map(|(m, p, _)| {
            let file = m.outputs.iter().find(|o| o.path.ends_with(".mcap"))?;
            let at = store.dir(&m.key).join(&file.path);
            let at = std::fs::canonicalize(&at).unwrap_or(at);
            let label = format!("{} {} {} run {}", p.env.name(), p.table(), super::method_label(p.method, p.iteration), p.run);
            Some((label, at.display().to_string()))
        })
        .collect();
    out.sort();
    out
}

/// The page for `markdown` (the text of report.md), with figures read from `dir`.
pub fn page(markdown: &str, dir: &Path, links: &Links) -> String {
    let mut body = String::new();
    let mut open_details = false;
    let lines: Vec<&str> = markdown.lines().collect();
    let mut para: Vec<&str> = Vec::new();
    let flush = |para: &mut Vec<&str>, body: &mut String| {
        if !para.is_empty() {
            let _ = writeln!(body, "<p>{}</p>", inline(&para.join(" ")));
            para.clear();
        }
    };
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        if line.starts_with('|') {
            flush(&mut para, &mut body);
            let start = i;
            while i < lines.len() && lines[i].starts_with('|') {
                i += 1;
            }
            body.push_str(&table(&lines[start..i]));
            continue;
        }
        if let Some(title) = line.strip_prefix("## ") {
            flush(&mut para, &mut body);
            if open_details {
                body.push_str("</details>\n");
                open_details = false;
            }
            if FOLDED.iter().any(|f| title.starts_with(f)) {
                let _ = writeln!(body, "<details><summary>{}</summary>", inline(title));
                open_details = true;
            } else {
                let _ = writeln!(body, "<h2>{}</h2>", inline(title));
            }
        } else if let Some(title) = line.strip_prefix("### ") {
            flush(&mut para, &mut body);
            let _ = writeln!(body, "<h3>{}</h3>", inline(title));
        } else if let Some(title) = line.strip_prefix("# ") {
            flush(&mut para, &mut body);
            let _ = writeln!(body, "<h1>{}</h1>", inline(title));
        } else if let Some(rest) = line.strip_prefix("![")
            && let Some(mid) = rest.find("](")
        {
            flush(&mut para, &mut body);
            let path = rest[mid + 2..].trim_end_matches(')');
            body.push_str(&figure(&rest[..mid], path, dir));
        } else if line.starts_with("- ") {
            flush(&mut para, &mut body);
            body.push_str("<ul>\n");
            while i < lines.len() && lines[i].starts_with("- ") {
                let _ = writeln!(body, "<li>{}</li>", inline(&lines[i][2..]));
                i += 1;
            }
            body.push_str("</ul>\n");
            continue;
        } else if line.trim().is_empty() {
            flush(&mut para, &mut body);
        } else {
            para.push(line);
        }
        i += 1;
    }
    flush(&mut para, &mut body);
    if open_details {
        body.push_str("</details>\n");
    }
    if !links.rollouts.is_empty() || !links.recordings.is_empty() {
        body.push_str("<details><summary>Files: rollouts (MCAP) and recordings (Rerun)</summary>\n<ul>\n");
        for r in &links.recordings {
            let _ = writeln!(body, "<li>Rerun recording: <a href=\"{}\">{}</a></li>", escape(r), escape(r));
        }
        for (label, at) in &links.rollouts {
            let _ = writeln!(body, "<li>{}: <a href=\"{}\">rollouts.mcap</a></li>", escape(label), escape(at));
        }
        body.push_str("</ul></details>\n");
    }
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>idrex report</title><style>{STYLE}</style></head>\n\
         <body>\n{body}<script>{SCRIPT}</script>\n</body></html>\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_becomes_one_page_with_its_tables_figures_and_folds() {
        let dir = std::env::temp_dir().join(format!("idrex-html-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("f.svg"), "<?xml version=\"1.0\"?>\n<svg width=\"10\"><rect/></svg>").unwrap();
        std::fs::write(dir.join("g.png"), [1u8, 2, 3, 4]).unwrap();
        let md = "- one\n- two\n## The answer\n\nD-REX `beats` **BC**, see [the docs](docs/x.md).\nSecond line.\n\n| a | b |\n|---|---|\n| 1 < 2 | x \\| y |\n\n\
                  ## Multi-BC clones against their sources\n\n| c |\n|---|\n| 3 |\n\n## Figures\n\n![A figure](f.svg)\n\n![Another](g.png)\n";
        let links = Links { rollouts: vec![("drex run 0".into(), "/s/k/rollouts.mcap".into())], recordings: vec!["a.rrd".into()] };
        let html = page(md, &dir, &links);
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(html.contains("<ul>\n<li>one</li>\n<li>two</li>\n</ul>\n<h2>The answer</h2>"), "{html}");
        assert!(html.contains("<p>D-REX <code>beats</code> <b>BC</b>, see <a href=\"docs/x.md\">the docs</a>. Second line.</p>"), "{html}");
        assert!(html.contains("<th>a</th><th>b</th>") && html.contains("<td>1 &lt; 2</td><td>x | y</td>"), "{html}");
        assert!(html.contains("<details><summary>Multi-BC clones against their sources</summary>"));
        assert!(html.contains("</details>\n<h2>Figures</h2>"), "the fold closes at the next section");
        assert!(html.contains("<figure><svg width=\"10\"><rect/></svg></figure>") && !html.contains("<?xml"));
        assert!(html.contains("src=\"data:image/png;base64,AQIDBA==\""));
        assert!(html.contains("href=\"/s/k/rollouts.mcap\"") && html.contains("href=\"a.rrd\""));
        assert!(!html.contains("src=\"http") && !html.contains("<link"), "nothing loads from outside");
        assert_eq!(base64(b"Man"), "TWFu");
        assert_eq!(base64(b"Ma"), "TWE=");
    }
}
