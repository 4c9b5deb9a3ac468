//! Data tables: CSV files read once (the `csv` crate) into columns of `f64`, and bound to
//! the columns a model reads.
//!
//! A table file has a header row of column names (identifiers), then numeric rows; blank
//! lines and lines starting with `#` are skipped. Every error is located in the file, as
//! `FILE:LINE:COL: error: MESSAGE` with the line quoted and a caret under the offending
//! field: a file that cannot be read, a bad number, a row of the wrong length, a missing
//! column, times that decrease.
//!
//! Both doors take their tables at run time: a loaded model reads the files its `table`
//! declarations name (or the ones `--table NAME=FILE` gives), and a model compiled by
//! `hybrid!` is built from a struct with one [`Table`] per declaration, so one binary runs
//! on any data.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mvad_dsl::diag::{render, Diagnostic};
use mvad_dsl::Span;

/// Where a table came from, for error messages: the file name and where its text can be had
/// again. The text itself is not kept (a table of 10⁷ rows is read as a stream, into its
/// columns only); an error that quotes it reads it back.
#[derive(Clone, Debug, Default, PartialEq)]
struct Source {
    file: String,
    origin: Origin,
    /// Byte offset of the header line.
    header: usize,
}

/// Where the text of a table is, for the errors that quote it.
#[derive(Clone, Debug, Default, PartialEq)]
enum Origin {
    /// Columns built in memory: no text.
    #[default]
    Memory,
    /// Text handed to [`Table::parse_csv`].
    Text(Arc<str>),
    /// A file, read again when an error quotes it.
    File(PathBuf),
}

impl Source {
    /// The text of the table (the file as it is now, invalid UTF-8 replaced; empty for a
    /// table built in memory or a file that can no longer be read).
    fn text(&self) -> String {
        match &self.origin {
            Origin::Memory => String::new(),
            Origin::Text(t) => t.to_string(),
            Origin::File(p) => std::fs::read(p)
                .map(|b| String::from_utf8_lossy(&b).into_owned())
                .unwrap_or_default(),
        }
    }
}

/// Where a table's data come from when a caller replaces the file its declaration names
/// (`--table NAME=FILE`, or `tables=` in Python).
#[derive(Clone, Debug, PartialEq)]
pub enum TableSource {
    /// A CSV file (relative to the working directory).
    File(PathBuf),
    /// Columns already in memory.
    Data(Table),
}

/// A data table: named columns of equal length. The columns are shared, not copied, by the
/// models bound to them ([`bind_columns`]) and by clones.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    names: Vec<String>,
    columns: Vec<Column>,
    source: Source,
}

/// A located error in a table (or a table that could not be read); `Display` gives the
/// rendered text, `FILE:LINE:COL: error: ...` first.
#[derive(Clone, Debug, PartialEq)]
pub struct TableError {
    /// The file name (or the table's name for a table built in memory).
    pub file: String,
    /// 1-based line and column.
    pub line: usize,
    /// 1-based column (in characters).
    pub col: usize,
    /// What is wrong.
    pub message: String,
    rendered: String,
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.rendered.trim_end())
    }
}

impl std::error::Error for TableError {}

/// Where in a table's text an error is.
enum At {
    /// A byte span.
    Span(Span),
    /// Field `i` of the line that starts at byte `start`.
    Field(usize, usize),
    /// The header line.
    Header,
}

impl TableError {
    /// The error at `at` in the table's text (read back from its origin).
    fn located(src: &Source, at: At, message: String) -> TableError {
        let text = src.text();
        let span = match at {
            At::Span(span) => span,
            At::Field(start, i) => field_span(&text, start, i),
            At::Header => {
                let h = src.header.min(text.len());
                let end = text[h..].find(['\n', '\r']).map_or(text.len(), |i| h + i);
                Span::new(h, end)
            }
        };
        let diag = Diagnostic::new(span, message.clone());
        let rendered = render(&src.file, &text, std::slice::from_ref(&diag));
        let (line, col) = mvad_dsl::SourceFile::new(&src.file, &text).line_col(span.start);
        TableError {
            file: src.file.clone(),
            line,
            col,
            message,
            rendered,
        }
    }

    fn unlocated(file: &str, message: String) -> TableError {
        TableError {
            file: file.to_string(),
            line: 1,
            col: 1,
            rendered: format!("{file}:1:1: error: {message}"),
            message,
        }
    }
}

impl Table {
    /// A table from columns held in memory (`name` is used in error messages). It is held to
    /// what a CSV file is held to: column names are distinct identifiers, every column has the
    /// same length and every value is a finite number.
    pub fn from_columns(name: &str, columns: Vec<(String, Vec<f64>)>) -> Result<Table, TableError> {
        for (i, (n, c)) in columns.iter().enumerate() {
            let earlier = columns[..i].iter().map(|(m, _)| m.as_str());
            if let Some(message) = column_name_error(n, earlier, "") {
                return Err(TableError::unlocated(name, message));
            }
            if let Some((row, v)) = c.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(TableError::unlocated(
                    name,
                    format!(
                        "`{v}` in column `{n}` (row {}) is not a finite number",
                        row + 1
                    ),
                ));
            }
        }
        let rows = columns.first().map_or(0, |(_, c)| c.len());
        if let Some((n, c)) = columns.iter().find(|(_, c)| c.len() != rows) {
            return Err(TableError::unlocated(
                name,
                format!("column `{n}` has {} rows, the first column {rows}", c.len()),
            ));
        }
        let (names, columns) = columns.into_iter().map(|(n, c)| (n, Arc::new(c))).unzip();
        Ok(Table {
            names,
            columns,
            source: Source {
                file: name.to_string(),
                ..Source::default()
            },
        })
    }

    /// Reads a CSV file as a stream: only the columns are kept, so memory is 8 bytes per
    /// value (the file's text is read again only to quote it in an error).
    pub fn read_csv(path: &Path) -> Result<Table, TableError> {
        let file = path.display().to_string();
        let reader = std::fs::File::open(path)
            .map_err(|e| TableError::unlocated(&file, format!("cannot read the table: {e}")))?;
        let src = Source {
            file,
            origin: Origin::File(path.to_path_buf()),
            header: 0,
        };
        Table::parse(src, reader)
    }

    /// Parses CSV text; `file` names it in error messages.
    pub fn parse_csv(file: &str, text: String) -> Result<Table, TableError> {
        let text: Arc<str> = Arc::from(text);
        let src = Source {
            file: file.to_string(),
            origin: Origin::Text(Arc::clone(&text)),
            header: 0,
        };
        Table::parse(src, text.as_bytes())
    }

    /// Reads the records of `input` (the `csv` crate's reader, one record buffer reused): the
    /// header, then rows of finite numbers, every error located at its field.
    fn parse(mut src: Source, input: impl std::io::Read) -> Result<Table, TableError> {
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .comment(Some(b'#'))
            // Fields are trimmed here, not by the reader (its trimming allocates per record).
            .flexible(true)
            .from_reader(input);
        let mut record = csv::ByteRecord::new();
        let mut names: Vec<String> = Vec::new();
        let mut columns: Vec<Vec<f64>> = Vec::new();
        loop {
            let more = match reader.read_byte_record(&mut record) {
                Ok(m) => m,
                Err(e) => {
                    let at = e.position().map_or(0, |p| p.byte() as usize);
                    let msg = format!("unreadable CSV: {e}");
                    return Err(TableError::located(
                        &src,
                        At::Span(Span::new(at, at + 1)),
                        msg,
                    ));
                }
            };
            if !more {
                break;
            }
            let start = record.position().map_or(0, |p| p.byte() as usize);
            if record.len() == 1 && record[0].trim_ascii().is_empty() {
                continue; // a blank line
            }
            if names.is_empty() {
                src.header = start;
                for i in 0..record.len() {
                    let field = utf8_field(&src, &record, start, i)?;
                    let earlier = names.iter().map(String::as_str);
                    if let Some(msg) = column_name_error(field, earlier, " in the header") {
                        return Err(TableError::located(&src, At::Field(start, i), msg));
                    }
                    names.push(field.to_string());
                }
                columns = vec![Vec::new(); names.len()];
                continue;
            }
            if record.len() != names.len() {
                let at = At::Field(start, record.len().min(names.len()));
                let msg = format!(
                    "this row has {} fields, the header {}",
                    record.len(),
                    names.len()
                );
                return Err(TableError::located(&src, at, msg));
            }
            for (i, column) in columns.iter_mut().enumerate() {
                let field = utf8_field(&src, &record, start, i)?;
                match field.parse::<f64>() {
                    Ok(v) if v.is_finite() => column.push(v),
                    _ => {
                        let msg =
                            format!("`{field}` in column `{}` is not a finite number", names[i]);
                        return Err(TableError::located(&src, At::Field(start, i), msg));
                    }
                }
            }
        }
        if names.is_empty() {
            let msg = "the table has no header row of column names".to_string();
            return Err(TableError::located(&src, At::Span(Span::new(0, 0)), msg));
        }
        // Shared as they are (moved, not copied).
        let columns = columns.into_iter().map(Arc::new).collect();
        Ok(Table {
            names,
            columns,
            source: src,
        })
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, |c| c.len())
    }

    /// The column names, in file order.
    pub fn column_names(&self) -> &[String] {
        &self.names
    }

    /// The values of column `name`.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.shared_column(name).map(|c| &c[..])
    }

    /// The shared buffer of column `name` (what [`bind_columns`] hands a model).
    fn shared_column(&self, name: &str) -> Option<&Column> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(&self.columns[i])
    }

    /// The error "the table has no column `name`", located at its header.
    fn missing_column(&self, table: &str, name: &str) -> TableError {
        let msg = format!(
            "table `{table}` has no column `{name}`; its columns are {}",
            self.names.join(", ")
        );
        TableError::located(&self.source, At::Header, msg)
    }

    /// The error "column `name` decreases" at row `row`.
    fn decreasing(&self, table: &str, name: &str, row: usize, event: &str) -> TableError {
        let i = self.names.iter().position(|n| n == name).unwrap_or(0);
        let c = &self.columns[i];
        let msg = format!(
            "column `{name}` of table `{table}` decreases here ({} after {}): the times of \
             event `{event}` must not decrease",
            c[row],
            c[row - 1]
        );
        match row_start(&self.source, row) {
            Some(start) => TableError::located(&self.source, At::Field(start, i), msg),
            None => TableError::unlocated(&self.source.file, msg),
        }
    }
}

/// Field i of `record` (the line starting at byte `start`) as trimmed UTF-8 text, or the
/// located error at its first invalid byte.
fn utf8_field<'r>(
    src: &Source,
    record: &'r csv::ByteRecord,
    start: usize,
    i: usize,
) -> Result<&'r str, TableError> {
    match std::str::from_utf8(&record[i]) {
        Ok(field) => Ok(field.trim()),
        Err(e) => {
            // The text before the first invalid byte is the file's, so the field starts where
            // it does in the file.
            let text = src.text();
            let field = field_span(&text, start, i);
            let lead = record[i].len() - record[i].trim_ascii_start().len();
            let at = field.start + e.valid_up_to() - lead.min(field.start + e.valid_up_to());
            let msg = "the table is not valid UTF-8 text".to_string();
            Err(TableError::located(
                src,
                At::Span(Span::new(at, at + 1)),
                msg,
            ))
        }
    }
}

/// The byte offset of the line of data row `row` (0-based, after the header), found by
/// reading the table's text again with the same rules (comments and blank lines skipped).
fn row_start(src: &Source, row: usize) -> Option<usize> {
    let text = src.text();
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .comment(Some(b'#'))
        .flexible(true)
        .from_reader(text.as_bytes());
    let mut record = csv::ByteRecord::new();
    let mut seen = 0usize; // non-blank records, the header first
    while reader.read_byte_record(&mut record).ok()? {
        if record.len() == 1 && record[0].trim_ascii().is_empty() {
            continue;
        }
        if seen == row + 1 {
            return record.position().map(|p| p.byte() as usize);
        }
        seen += 1;
    }
    None
}

/// A column's values, shared by the table and the models bound to it.
pub type Column = Arc<Vec<f64>>;

/// What a model needs from its tables.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TableNeeds<'a> {
    /// The declared table names, in declaration order.
    pub tables: Vec<&'a str>,
    /// The columns read, as (table index, column name); column c of the model is entry c.
    pub columns: Vec<(usize, &'a str)>,
    /// Columns that are the bare times of an `at each` event: (column index, event name).
    pub times: Vec<(usize, &'a str)>,
}

/// The columns a model reads, taken from its tables (one per declared table, in declaration
/// order), with the number of rows of each table. Checks that every column exists and that
/// the columns used bare as `at each` times do not decrease.
pub fn bind_columns(
    needs: &TableNeeds<'_>,
    tables: &[&Table],
) -> Result<(Vec<Column>, Vec<usize>), TableError> {
    let mut columns = Vec::with_capacity(needs.columns.len());
    for &(t, name) in &needs.columns {
        let (Some(table), Some(decl)) = (tables.get(t), needs.tables.get(t)) else {
            return Err(TableError::unlocated(
                name,
                format!("no table given for column `{name}`"),
            ));
        };
        match table.shared_column(name) {
            Some(c) => columns.push(Arc::clone(c)),
            None => return Err(table.missing_column(decl, name)),
        }
    }
    for &(c, event) in &needs.times {
        let (t, name) = needs.columns[c];
        if let Some(row) = columns[c].windows(2).position(|w| w[1] < w[0]) {
            return Err(tables[t].decreasing(needs.tables[t], name, row + 1, event));
        }
    }
    Ok((columns, tables.iter().map(|t| t.rows()).collect()))
}

/// Why `name` cannot be a column after the columns `earlier` (a CSV header's fields, or the
/// columns given in memory; `among` ends the second message: " in the header"): not an
/// identifier, or a name given twice.
fn column_name_error<'a>(
    name: &str,
    mut earlier: impl Iterator<Item = &'a str>,
    among: &str,
) -> Option<String> {
    if !is_identifier(name) {
        Some(format!(
            "column name `{name}` is not an identifier (letters, digits and `_`, not starting \
             with a digit)"
        ))
    } else if earlier.any(|n| n == name) {
        Some(format!("column `{name}` appears twice{among}"))
    } else {
        None
    }
}

/// Whether `s` is a column name: a letter or `_`, then letters, digits and `_`.
fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The byte span of field `i` of the line starting at `start` (fields split at commas,
/// blanks trimmed; the line's end for a missing field).
fn field_span(text: &str, start: usize, i: usize) -> Span {
    let end = text[start..]
        .find(['\n', '\r'])
        .map_or(text.len(), |k| start + k);
    let line = &text[start..end];
    let mut offset = 0;
    for (k, field) in line.split(',').enumerate() {
        if k == i {
            let lead = field.len() - field.trim_start().len();
            let a = start + offset + lead;
            return Span::new(a, a + field.trim().len().max(1));
        }
        offset += field.len() + 1;
    }
    Span::new(end, end + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Table, TableError> {
        Table::parse_csv("q.csv", text.to_string())
    }

    #[test]
    fn reads_columns_skipping_comments_and_blank_lines() {
        let t = parse("# arrivals\nt, s\n0.5, 1\n\n1.25,2e-1\n").expect("parses");
        assert_eq!(t.rows(), 2);
        assert_eq!(t.column("t"), Some(&[0.5, 1.25][..]));
        assert_eq!(t.column("s"), Some(&[1.0, 0.2][..]));
        assert_eq!(t.column("x"), None);
    }

    #[test]
    fn errors_are_located_in_the_file() {
        let e = parse("t,s\n1,2\n3,abc\n").unwrap_err();
        assert_eq!((e.line, e.col), (3, 3), "{e}");
        assert!(
            e.to_string()
                .starts_with("q.csv:3:3: error: `abc` in column `s` is not a finite number"),
            "{e}"
        );
        assert!(e.to_string().contains("^^^"), "{e}");
        let e = parse("t,s\n1,2\n3\n").unwrap_err();
        assert_eq!(e.line, 3, "{e}");
        let e = parse("t,1s\n").unwrap_err();
        assert_eq!((e.line, e.col), (1, 3), "{e}");
        let e = parse("# nothing\n").unwrap_err();
        assert!(e.message.contains("no header"), "{e}");
        let e = Table::read_csv(Path::new("/nonexistent/q.csv")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent/q.csv:1:1: error: cannot read"),
            "{e}"
        );
    }

    /// A file is read as a stream; its errors still quote the line, read back from the file,
    /// including the row of a decreasing time found only when the model binds it.
    #[test]
    fn a_file_streams_and_its_errors_quote_the_line() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("q.csv");
        let read = |text: &[u8]| {
            std::fs::write(&path, text).expect("write");
            Table::read_csv(&path)
        };
        let t = read(b"# c\nt,s\n\n1, 2\n3,4\n").expect("reads");
        assert_eq!(t.column("s"), Some(&[2.0, 4.0][..]));
        let e = read(b"t,s\n1,2\n3, 4x\n").unwrap_err();
        assert_eq!((e.line, e.col), (3, 4), "{e}");
        assert!(e.to_string().contains("3, 4x\n  |    ^^"), "{e}");
        let e = read(b"t,s\n1,2\n3,caf\xe9\n").unwrap_err();
        assert_eq!((e.line, e.col), (3, 6), "{e}");
        assert!(e.message.contains("not valid UTF-8"), "{e}");
        let t = read(b"t,s\n1,2\n# c\n\n3,4\n2,5\n").expect("reads");
        let needs = TableNeeds {
            tables: vec!["arrivals"],
            columns: vec![(0, "t")],
            times: vec![(0, "arrive")],
        };
        let e = bind_columns(&needs, &[&t]).unwrap_err();
        assert_eq!((e.line, e.col), (6, 1), "{e}");
        assert!(e.to_string().contains("2,5"), "{e}");
    }

    #[test]
    fn binding_checks_columns_and_monotone_times() {
        let t = parse("t,s\n1,2\n3,4\n2,5\n").expect("parses");
        let needs = TableNeeds {
            tables: vec!["arrivals"],
            columns: vec![(0, "s"), (0, "t")],
            times: vec![],
        };
        let (cols, rows) = bind_columns(&needs, &[&t]).expect("binds");
        assert_eq!(cols[0][..], [2.0, 4.0, 5.0]);
        assert_eq!(cols[1][..], [1.0, 3.0, 2.0]);
        // Bound, not copied: the model shares the table's buffers.
        assert!(Arc::ptr_eq(&cols[0], t.shared_column("s").expect("s")));
        assert_eq!(rows, vec![3]);
        let needs = TableNeeds {
            times: vec![(1, "arrive")],
            ..needs
        };
        let e = bind_columns(&needs, &[&t]).unwrap_err();
        assert_eq!((e.line, e.col), (4, 1), "{e}");
        assert!(e.message.contains("decreases"), "{e}");
        let needs = TableNeeds {
            tables: vec!["arrivals"],
            columns: vec![(0, "w")],
            times: vec![],
        };
        let e = bind_columns(&needs, &[&t]).unwrap_err();
        assert_eq!((e.line, e.col), (1, 1), "{e}");
        assert!(
            e.message.contains("no column `w`; its columns are t, s"),
            "{e}"
        );
    }

    #[test]
    fn columns_in_memory_are_held_to_what_a_file_is_held_to() {
        let col = |n: &str, v: &[f64]| (n.to_string(), v.to_vec());
        let ok = Table::from_columns(
            "arrivals",
            vec![col("t", &[0.0, 1.0]), col("s", &[1.0, 2.0])],
        );
        assert_eq!(ok.expect("finite columns").rows(), 2);
        for (columns, says) in [
            (
                vec![col("t", &[0.0, f64::NAN])],
                "`NaN` in column `t` (row 2) is not a finite",
            ),
            (
                vec![col("t", &[f64::INFINITY])],
                "`inf` in column `t` (row 1)",
            ),
            (
                vec![col("t", &[1.0]), col("s", &[1.0, 2.0])],
                "column `s` has 2 rows",
            ),
            (
                vec![col("1t", &[1.0])],
                "column name `1t` is not an identifier",
            ),
            (
                vec![col("t", &[1.0]), col("t", &[2.0])],
                "column `t` appears twice",
            ),
        ] {
            let e = Table::from_columns("arrivals", columns).unwrap_err();
            assert!(e.to_string().starts_with("arrivals:1:1: error: "), "{e}");
            assert!(e.message.contains(says), "{e}");
        }
    }
}
