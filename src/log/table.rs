//! One writer for every table idrex prints. A table is typed rows ([`Row`]) or a built
//! [`Table`] (where the columns depend on the data, as in `exp show`); the same cells come out
//! as CSV (RFC 4180), JSON (an array of objects, keys in column order), markdown, an aligned
//! text table for the terminal, or an HTML table.
use std::fmt::Write as _;

/// One cell, typed: numbers stay numbers in CSV and JSON, and a missing figure is empty (CSV)
/// or null (JSON), never "NaN".
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    Text(String),
    Int(Option<u64>),
    /// Shown with `decimals` in markdown, text and HTML; full precision in CSV and JSON.
    Num(Option<f64>, usize),
    Flag(bool),
    /// A value with its 95 % interval: one cell for a reader, three columns (`name`,
    /// `name_ci_low`, `name_ci_high`) in CSV and JSON.
    Estimate(Option<(f64, f64, f64)>, usize),
}

impl Cell {
    pub fn num(x: f64) -> Cell {
        Cell::Num(Some(x).filter(|v| v.is_finite()), 1)
    }

    pub fn opt(x: Option<f64>, decimals: usize) -> Cell {
        Cell::Num(x.filter(|v| v.is_finite()), decimals)
    }

    pub fn int(x: usize) -> Cell {
        Cell::Int(Some(x as u64))
    }

    pub fn text(s: impl Into<String>) -> Cell {
        Cell::Text(s.into())
    }

    fn raw(&self) -> String {
        match self {
            Cell::Text(s) => s.clone(),
            Cell::Int(v) => v.map_or(String::new(), |v| v.to_string()),
            Cell::Num(v, _) => v.map_or(String::new(), |v| format!("{v:?}")),
            Cell::Flag(b) => b.to_string(),
            Cell::Estimate(..) => self.parts().iter().map(Cell::raw).collect::<Vec<_>>().join(" "),
        }
    }

    /// An estimate's three numbers (missing ones for any other cell in its column).
    fn parts(&self) -> [Cell; 3] {
        match self {
            Cell::Estimate(Some((v, lo, hi)), d) => [Cell::Num(Some(*v), *d), Cell::Num(Some(*lo), *d), Cell::Num(Some(*hi), *d)],
            _ => [Cell::Num(None, 0), Cell::Num(None, 0), Cell::Num(None, 0)],
        }
    }

    /// For a reader: rounded, and "n/a" for a figure that could not be computed.
    pub fn shown(&self) -> String {
        match self {
            Cell::Num(None, _) | Cell::Int(None) | Cell::Estimate(None, _) => "n/a".into(),
            &Cell::Num(Some(v), d) => format!("{v:.d$}"),
            &Cell::Estimate(Some((v, lo, hi)), d) => format!("{v:.d$} [{lo:.d$}, {hi:.d$}]"),
            Cell::Flag(b) => (if *b { "yes" } else { "no" }).into(),
            _ => self.raw(),
        }
    }

    fn json(&self) -> serde_json::Value {
        match self {
            Cell::Text(s) => s.clone().into(),
            Cell::Int(v) => v.map_or(serde_json::Value::Null, Into::into),
            Cell::Num(v, _) => v.map_or(serde_json::Value::Null, Into::into),
            Cell::Flag(b) => (*b).into(),
            Cell::Estimate(..) => self.parts()[0].json(),
        }
    }
}

/// A row type of a fixed table: its header once, its cells per row.
pub trait Row {
    fn header() -> Vec<&'static str>;
    fn cells(&self) -> Vec<Cell>;
}

/// A table with its columns named: what every writer takes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    pub columns: Vec<String>,
    pub rows: Vec<Vec<Cell>>,
}

/// The widest cell of a text table.
pub const TEXT_WIDTH: usize = 40;

/// The output formats of a tabular command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Aligned columns for a terminal.
    Text,
    Csv,
    Json,
    Markdown,
}

impl Table {
    pub fn of<R: Row>(rows: &[R]) -> Table {
        Table { columns: R::header().into_iter().map(String::from).collect(), rows: rows.iter().map(Row::cells).collect() }
    }

    /// The columns whose `keep` is true.
    pub fn keep(&self, keep: &[bool]) -> Table {
        let pick = |v: &[Cell]| v.iter().zip(keep).filter(|(_, k)| **k).map(|(c, _)| c.clone()).collect();
        Table {
            columns: self.columns.iter().zip(keep).filter(|(_, k)| **k).map(|(c, _)| c.clone()).collect(),
            rows: self.rows.iter().map(|r| pick(r)).collect(),
        }
    }

    pub fn write(&self, format: Format) -> String {
        match format {
            Format::Text => self.text(),
            Format::Csv => self.csv(),
            Format::Json => self.json(),
            Format::Markdown => self.markdown(),
        }
    }

    /// The columns and rows with every estimate column spread over three.
    fn flat(&self) -> (Vec<String>, Vec<Vec<Cell>>) {
        let spread: Vec<bool> = (0..self.columns.len()).map(|i| self.rows.iter().any(|r| matches!(r[i], Cell::Estimate(..)))).collect();
        let mut columns = Vec::new();
        for (c, &s) in self.columns.iter().zip(&spread) {
            columns.push(c.clone());
            if s {
                columns.extend([format!("{c}_ci_low"), format!("{c}_ci_high")]);
            }
        }
        let rows = self
            .rows
            .iter()
            .map(|r| r.iter().zip(&spread).flat_map(|(c, &s)| if s { c.parts().to_vec() } else { vec![c.clone()] }).collect())
            .collect();
        (columns, rows)
    }

    pub fn csv(&self) -> String {
        fn field(s: &str) -> String {
            if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
        }
        let (columns, rows) = self.flat();
        let mut out = columns.iter().map(|c| field(c)).collect::<Vec<_>>().join(",");
        out.push('\n');
        for r in &rows {
            out.push_str(&r.iter().map(|c| field(&c.raw())).collect::<Vec<_>>().join(","));
            out.push('\n');
        }
        out
    }

    pub fn json(&self) -> String {
        let (columns, rows) = self.flat();
        let rows: Vec<String> = rows
            .iter()
            .map(|r| {
                let fields: Vec<String> =
                    columns.iter().zip(r).map(|(k, c)| format!("{}: {}", serde_json::Value::from(k.as_str()), c.json())).collect();
                format!("  {{{}}}", fields.join(", "))
            })
            .collect();
        if rows.is_empty() { "[]\n".into() } else { format!("[\n{}\n]\n", rows.join(",\n")) }
    }

    pub fn markdown(&self) -> String {
        let line = |cells: Vec<String>| format!("| {} |\n", cells.iter().map(|c| c.replace('|', "\\|")).collect::<Vec<_>>().join(" | "));
        let mut out = line(self.columns.clone());
        out.push_str(&format!("|{}\n", "---|".repeat(self.columns.len())));
        for r in &self.rows {
            out.push_str(&line(r.iter().map(Cell::shown).collect()));
        }
        out
    }

    /// Cells past [`TEXT_WIDTH`] characters are cut (CSV and JSON carry them whole).
    pub fn text(&self) -> String {
        let cut = |s: String| if s.chars().count() > TEXT_WIDTH { s.chars().take(TEXT_WIDTH - 1).chain(['…']).collect() } else { s };
        let shown: Vec<Vec<String>> = self.rows.iter().map(|r| r.iter().map(|c| cut(c.shown())).collect()).collect();
        let width = |i: usize| shown.iter().map(|r| r[i].chars().count()).chain([self.columns[i].chars().count()]).max().unwrap_or(0);
        let widths: Vec<usize> = (0..self.columns.len()).map(width).collect();
        let mut out = String::new();
        for cells in std::iter::once(&self.columns).chain(&shown) {
            let padded: Vec<String> = cells.iter().zip(&widths).map(|(c, w)| format!("{c:<w$}")).collect();
            let _ = writeln!(out, "{}", padded.join("  ").trim_end());
        }
        out
    }

    /// A `<table>` whose numeric cells carry their full value (`data-v`) for sorting.
    pub fn html(&self) -> String {
        let mut out = String::from("<table class=\"sortable\"><thead><tr>");
        for c in &self.columns {
            let _ = write!(out, "<th>{}</th>", escape(c));
        }
        out.push_str("</tr></thead><tbody>\n");
        for r in &self.rows {
            out.push_str("<tr>");
            for c in r {
                match c {
                    Cell::Num(Some(v), _) => {
                        let _ = write!(out, "<td class=\"n\" data-v=\"{v:?}\">{}</td>", c.shown());
                    }
                    Cell::Estimate(Some((v, ..)), _) => {
                        let _ = write!(out, "<td class=\"n\" data-v=\"{v:?}\">{}</td>", c.shown());
                    }
                    Cell::Int(Some(v)) => {
                        let _ = write!(out, "<td class=\"n\" data-v=\"{v}\">{v}</td>");
                    }
                    _ => {
                        let _ = write!(out, "<td>{}</td>", escape(&c.shown()));
                    }
                }
            }
            out.push_str("</tr>\n");
        }
        out.push_str("</tbody></table>\n");
        out
    }
}

/// Text made safe inside HTML elements and attribute values.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Table {
        Table {
            columns: vec!["name".into(), "n".into(), "score".into(), "ok".into()],
            rows: vec![
                vec![Cell::text("a, \"quoted\""), Cell::int(3), Cell::opt(Some(0.125), 2), Cell::Flag(true)],
                vec![Cell::text("b|c"), Cell::Int(None), Cell::num(f64::NAN), Cell::Flag(false)],
            ],
        }
    }

    #[test]
    fn one_table_in_every_format() {
        let t = table();
        assert_eq!(t.csv(), "name,n,score,ok\n\"a, \"\"quoted\"\"\",3,0.125,true\nb|c,,,false\n");
        let json: serde_json::Value = serde_json::from_str(&t.json()).unwrap();
        assert_eq!(json[0]["name"], "a, \"quoted\"");
        assert_eq!(json[0]["score"], 0.125);
        assert!(json[1]["score"].is_null() && json[1]["n"].is_null());
        assert!(t.json().find("\"name\"").unwrap() < t.json().find("\"score\"").unwrap(), "keys in column order");
        let md = t.markdown();
        assert!(md.contains("| a, \"quoted\" | 3 | 0.12 | yes |") && md.contains("| b\\|c | n/a | n/a | no |"), "{md}");
        let text = t.text();
        assert_eq!(text.lines().next().unwrap(), "name         n    score  ok");
        assert!(t.html().contains("<td class=\"n\" data-v=\"0.125\">0.12</td>") && t.html().contains("&quot;quoted&quot;"));
        assert_eq!(Table::default().json(), "[]\n");
        let e = Table {
            columns: vec!["x".into(), "k".into()],
            rows: vec![vec![Cell::Estimate(Some((2.0, 1.0, 3.5)), 1), Cell::int(1)], vec![Cell::Estimate(None, 1), Cell::int(2)]],
        };
        assert_eq!(e.csv(), "x,x_ci_low,x_ci_high,k\n2.0,1.0,3.5,1\n,,,2\n");
        assert!(e.markdown().contains("| 2.0 [1.0, 3.5] | 1 |") && e.markdown().contains("| n/a | 2 |"));
        assert!(e.json().contains("\"x_ci_high\": 3.5"));
        let long = Table { columns: vec!["p".into()], rows: vec![vec![Cell::text("y".repeat(100))]] };
        assert_eq!(long.text().lines().nth(1).unwrap().chars().count(), TEXT_WIDTH);
    }
}
