//! Output helpers: number formatting and plain-text tables; the JSON pieces several
//! commands share come from the library's [`mvad::json`] (one builder for every front end).

pub use mvad::json::{diagnostics_json, num, stats_json};
use mvad::runtime::solution::Diagnostic;
use serde_json::Value;

/// Pretty JSON text with a final newline.
pub fn json_text(v: &Value) -> String {
    let mut s =
        serde_json::to_string_pretty(v).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    s.push('\n');
    s
}

/// A number with `sig` significant digits, fixed notation for moderate magnitudes and
/// scientific otherwise (like C's `%g`).
pub fn g(x: f64, sig: usize) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".to_string();
    }
    let sig = sig.max(1);
    let exp = x.abs().log10().floor() as i32;
    if (-4..sig as i32).contains(&exp) {
        let decimals = (sig as i32 - 1 - exp).max(0) as usize;
        let s = format!("{x:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        let s = format!("{x:.prec$e}", prec = sig - 1);
        // Trim zeros of the mantissa: 1.500e-7 -> 1.5e-7.
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
}

/// A plain-text table: a header row, a rule, and left-aligned columns.
#[derive(Debug, Default)]
pub struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with these column titles.
    pub fn new<S: AsRef<str>>(header: &[S]) -> Self {
        Table {
            header: header.iter().map(|s| s.as_ref().to_string()).collect(),
            rows: Vec::new(),
        }
    }
    /// Appends a row (missing cells print empty).
    pub fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }
    /// Whether no rows were added.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
    /// The text, each line ending in a newline.
    pub fn render(&self) -> String {
        let ncol = self
            .rows
            .iter()
            .map(Vec::len)
            .chain(std::iter::once(self.header.len()))
            .max()
            .unwrap_or(0);
        let mut width = vec![0usize; ncol];
        for row in std::iter::once(&self.header).chain(&self.rows) {
            for (j, c) in row.iter().enumerate() {
                width[j] = width[j].max(c.chars().count());
            }
        }
        let line = |row: &[String]| {
            let mut s = String::new();
            for (j, w) in width.iter().enumerate() {
                let c = row.get(j).map(String::as_str).unwrap_or("");
                s.push_str(c);
                if j + 1 < ncol {
                    let pad = w - c.chars().count() + 2;
                    s.extend(std::iter::repeat_n(' ', pad));
                }
            }
            s.trim_end().to_string() + "\n"
        };
        let mut out = line(&self.header);
        let total: usize = width.iter().sum::<usize>() + 2 * ncol.saturating_sub(1);
        out.push_str(&"-".repeat(total));
        out.push('\n');
        for r in &self.rows {
            out.push_str(&line(r));
        }
        out
    }
}

/// Table titles: the `fixed` ones, then `PREFIX NAME` for each parameter in `wrt`.
pub fn param_header(fixed: &[&str], prefix: &str, names: &[String], wrt: &[usize]) -> Vec<String> {
    fixed
        .iter()
        .map(|s| s.to_string())
        .chain(wrt.iter().map(|&k| format!("{prefix}{}", names[k])))
        .collect()
}

/// `items` joined by `sep`, or `empty` when there are none.
pub fn join_or<S: AsRef<str>>(items: &[S], sep: &str, empty: &str) -> String {
    if items.is_empty() {
        empty.to_string()
    } else {
        items
            .iter()
            .map(AsRef::as_ref)
            .collect::<Vec<_>>()
            .join(sep)
    }
}

/// The most event rows a human-readable table shows (`--json` always prints them all).
pub const MAX_EVENT_ROWS: usize = 20;

/// The most event times a one-line list shows (`fdcheck`).
pub const MAX_LISTED_TIMES: usize = 5;

/// The line after a table cut at [`MAX_EVENT_ROWS`] of `total` events; empty when nothing
/// was cut.
pub fn more_events(total: usize) -> String {
    if total > MAX_EVENT_ROWS {
        format!(
            "… and {} more events (--json lists 1000, --all-events all)\n",
            total - MAX_EVENT_ROWS
        )
    } else {
        String::new()
    }
}

/// The first [`MAX_LISTED_TIMES`] of `items` joined by `sep`, then `… and N more`; `empty`
/// when there are none.
pub fn capped_list<S: AsRef<str>>(items: &[S], sep: &str, empty: &str) -> String {
    let shown = items.len().min(MAX_LISTED_TIMES);
    let mut s = join_or(&items[..shown], sep, empty);
    if items.len() > shown {
        s.push_str(&format!("{sep}… and {} more", items.len() - shown));
    }
    s
}

/// Diagnostics as text lines (`warning: zeno at t = 1.9: ...`), empty if none.
pub fn diagnostics_text(diags: &[Diagnostic]) -> String {
    let mut s = String::new();
    for d in diags {
        s.push_str(&format!(
            "warning: {} at t = {}: {}\n",
            d.kind.name(),
            g(d.t, 10),
            d.message
        ));
    }
    s
}

/// Cosine similarity of two vectors (1 when both vanish, 0 when only one does).
pub fn cosine(a: &[f64], b: &[f64]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    if na == 0.0 && nb == 0.0 {
        1.0
    } else if na == 0.0 || nb == 0.0 {
        0.0
    } else {
        dot / (na * nb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn general_number_format() {
        assert_eq!(g(2.8314408141470055, 6), "2.83144");
        assert_eq!(g(0.0, 6), "0");
        assert_eq!(g(1e-9, 3), "1e-9");
        assert_eq!(g(-1.5e-7, 4), "-1.5e-7");
        assert_eq!(g(123456789.0, 4), "1.235e8");
        assert_eq!(g(100.0, 6), "100");
        assert_eq!(g(0.001234, 3), "0.00123");
        assert_eq!(g(f64::NAN, 3), "NaN");
    }

    #[test]
    fn table_aligns_columns() {
        let mut t = Table::new(&["a", "long header"]);
        t.row(vec!["12345".into(), "x".into()]);
        let text = t.render();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "a      long header");
        assert_eq!(lines[1], "-".repeat(18));
        assert_eq!(lines[2], "12345  x");
    }

    #[test]
    fn headers_and_lists() {
        let names: Vec<String> = ["e", "g", "h0"].map(String::from).to_vec();
        assert_eq!(
            param_header(&["#", "t"], "dt/d", &names, &[2, 0]),
            ["#", "t", "dt/dh0", "dt/de"]
        );
        assert_eq!(join_or(&names, ", ", "-"), "e, g, h0");
        assert_eq!(join_or::<String>(&[], ", ", "-"), "-");
        let seven: Vec<String> = (1..=7).map(|i| i.to_string()).collect();
        assert_eq!(
            capped_list(&seven, "; ", "-"),
            "1; 2; 3; 4; 5; … and 2 more"
        );
        assert_eq!(capped_list(&seven[..5], "; ", "-"), "1; 2; 3; 4; 5");
        assert_eq!(capped_list::<String>(&[], "; ", "-"), "-");
        assert_eq!(more_events(MAX_EVENT_ROWS), "");
        assert_eq!(
            more_events(12_000),
            "… and 11980 more events (--json lists 1000, --all-events all)\n"
        );
    }

    #[test]
    fn cosine_similarity() {
        assert_relative_eq!(cosine(&[1.0, 0.0], &[1.0, 1.0]), 0.5f64.sqrt());
        assert_eq!(cosine(&[0.0], &[0.0]), 1.0);
        assert_eq!(cosine(&[0.0], &[2.0]), 0.0);
        assert_relative_eq!(cosine(&[2.0, -1.0], &[-4.0, 2.0]), -1.0);
    }
}
