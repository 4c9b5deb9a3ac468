//! Loading `.hyb` files into run-time models.
//!
//! [`load`] reads a file, [`load_str`] takes text that is already in memory; both return an
//! [`InterpretedModel`] (dynamic sizes, the tape evaluator) or a [`LoadError`] whose text is
//! ready to print: for a model error, one block per error whose first line is
//! `FILE:LINE:COL: error: MESSAGE`, then the offending line quoted and a caret under the
//! offending text. Problems below the grammar are located errors too: an empty file, bytes
//! that are not UTF-8 (the first bad byte is located) and binary data (the first control
//! character other than tab, newline or carriage return is located).
//!
//! No input makes these functions panic or recurse without bound: nesting depth is
//! limited by the front end before any recursive pass runs.

use std::borrow::Cow;
use std::fmt;
use std::io::Read;
use std::path::Path;

use mvad_dsl::diag::{render, Diagnostic};
use mvad_dsl::Span;

use crate::interp::InterpretedModel;
use crate::table::{Table, TableError, TableSource};

/// The largest model file [`load`] reads (16 MiB).
pub const MAX_FILE_BYTES: u64 = 16 << 20;

/// Why a model could not be loaded; `Display` gives the rendered text.
#[derive(Clone, Debug, PartialEq)]
pub enum LoadError {
    /// The file could not be read.
    Io {
        /// The path as given.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// A data table could not be read or does not fit the model: located in its file.
    Table(TableError),
    /// `--table NAME=FILE` names a table the model does not declare.
    UnknownTable {
        /// The name given.
        name: String,
        /// The declared tables.
        known: Vec<String>,
    },
    /// The text is not a valid model: located errors.
    Model {
        /// The file name used in the rendering.
        file: String,
        /// The errors (byte spans into the text, or into its lossy UTF-8 decoding).
        diagnostics: Vec<Diagnostic>,
        /// `FILE:LINE:COL: error: ...` blocks, the line quoted, carets.
        rendered: String,
    },
}

impl LoadError {
    /// The located errors (empty for an I/O failure).
    pub fn diagnostics(&self) -> &[Diagnostic] {
        match self {
            LoadError::Model { diagnostics, .. } => diagnostics,
            _ => &[],
        }
    }
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadError::Io { path, reason } => {
                write!(f, "{path}: error: cannot read file: {reason}")
            }
            LoadError::Model { rendered, .. } => f.write_str(rendered.trim_end()),
            LoadError::Table(e) => write!(f, "{e}"),
            LoadError::UnknownTable { name, known } => {
                let known = if known.is_empty() {
                    "the model declares no tables".to_string()
                } else {
                    format!("its tables are {}", known.join(", "))
                };
                write!(f, "error: the model has no table `{name}`; {known}")
            }
        }
    }
}

impl std::error::Error for LoadError {}

/// Reads and compiles the `.hyb` file at `path` and reads the tables it declares (paths
/// relative to the model file); errors are rendered with the file's name.
pub fn load(path: &Path) -> Result<InterpretedModel, LoadError> {
    load_with_tables(path, &[])
}

/// [`load`], with some tables replaced: `(NAME, source)` takes table NAME from `source` (a
/// file relative to the working directory, or data in memory) instead of the file the model
/// names.
pub fn load_with_tables(
    path: &Path,
    tables: &[(String, TableSource)],
) -> Result<InterpretedModel, LoadError> {
    let mut model = read_model(path)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    bind_tables(&mut model, dir, tables)?;
    Ok(model)
}

/// Reads the tables `model` declares (files relative to `dir`, or the sources `overrides`
/// gives, the last one for a name given twice) and binds them.
pub fn bind_tables(
    model: &mut InterpretedModel,
    dir: &Path,
    overrides: &[(String, TableSource)],
) -> Result<(), LoadError> {
    let decls = model.table_decls().to_vec();
    if let Some((name, _)) = overrides
        .iter()
        .find(|(n, _)| !decls.iter().any(|(d, _)| d == n))
    {
        return Err(LoadError::UnknownTable {
            name: name.clone(),
            known: decls.into_iter().map(|(n, _)| n).collect(),
        });
    }
    if decls.is_empty() {
        return Ok(());
    }
    let source = |name: &str| {
        overrides
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, s)| s)
    };
    let tables = decls
        .iter()
        .map(|(name, file)| {
            Ok(match source(name) {
                Some(TableSource::Data(t)) => Cow::Borrowed(t),
                Some(TableSource::File(p)) => Cow::Owned(Table::read_csv(p)?),
                None => Cow::Owned(Table::read_csv(&dir.join(file))?),
            })
        })
        .collect::<Result<Vec<Cow<'_, Table>>, TableError>>()
        .map_err(LoadError::Table)?;
    let refs: Vec<&Table> = tables.iter().map(|t| t.as_ref()).collect();
    model.bind_tables(&refs).map_err(LoadError::Table)
}

fn read_model(path: &Path) -> Result<InterpretedModel, LoadError> {
    let name = path.display().to_string();
    if path.is_dir() {
        return Err(LoadError::Io {
            path: name,
            reason: "is a directory".into(),
        });
    }
    let io = |e: std::io::Error| LoadError::Io {
        path: name.clone(),
        reason: e.to_string(),
    };
    // Read at most one byte past the limit, so an endless source (`/dev/zero`) ends.
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_FILE_BYTES + 1).read_to_end(&mut bytes))
        .map_err(io)?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(LoadError::Io {
            path: name,
            reason: format!("larger than {} MiB; not a model", MAX_FILE_BYTES >> 20),
        });
    }
    load_bytes(&name, &bytes)
}

/// Compiles model text held in memory; `name` is the file name used in error messages. The
/// tables the model declares are not read: bind them with [`bind_tables`].
pub fn load_str(name: &str, src: &str) -> Result<InterpretedModel, LoadError> {
    if let Some(d) = precheck(src) {
        return Err(clipped_error(name, src, d));
    }
    InterpretedModel::from_source(src).map_err(|diags| model_error(name, src, diags))
}

/// Compiles raw bytes: [`load_str`] after checking that they are UTF-8 (the first invalid
/// byte is reported as a located error).
pub fn load_bytes(name: &str, bytes: &[u8]) -> Result<InterpretedModel, LoadError> {
    match std::str::from_utf8(bytes) {
        Ok(src) => load_str(name, src),
        Err(e) => {
            // Up to the first bad byte the lossy text equals the original, so line and
            // column are those of the file.
            let at = e.valid_up_to();
            let lossy = String::from_utf8_lossy(bytes);
            let len = e.error_len().unwrap_or(bytes.len() - at);
            let d = Diagnostic::new(
                Span::new(at, at + '\u{FFFD}'.len_utf8()),
                format!(
                    "the file is not valid UTF-8 text (byte 0x{:02X} at offset {at}{})",
                    bytes[at],
                    if len > 1 {
                        format!(", {len} bad bytes")
                    } else {
                        String::new()
                    }
                ),
            )
            .with_help("a `.hyb` model is UTF-8 text");
            Err(clipped_error(name, &lossy, d))
        }
    }
}

/// Errors the grammar would report less clearly: an empty (or blank) file, binary data.
fn precheck(src: &str) -> Option<Diagnostic> {
    if src.trim().is_empty() {
        return Some(
            Diagnostic::new(
                Span::new(0, 0),
                "empty model file; expected `model NAME { ... }`",
            )
            .with_help("a model starts with `model NAME {` and declares at least one `state`"),
        );
    }
    let (pos, c) = src
        .char_indices()
        .find(|&(_, c)| c.is_control() && !matches!(c, '\t' | '\n' | '\r'))?;
    Some(
        Diagnostic::new(
            Span::new(pos, pos + c.len_utf8()),
            format!(
                "unexpected character U+{:04X}; the file looks like binary data, not a model",
                c as u32
            ),
        )
        .with_help("a `.hyb` model is plain text"),
    )
}

/// Like [`model_error`] for an error found below the grammar, but quoting the offending
/// line only up to a few dozen characters past the error, so a binary file does not
/// flood the terminal.
fn clipped_error(name: &str, src: &str, d: Diagnostic) -> LoadError {
    let end = d.span.end.min(src.len());
    let line_end = src[end..].find('\n').map_or(src.len(), |i| end + i);
    let mut cut = src[end..line_end]
        .char_indices()
        .nth(40)
        .map_or(line_end, |(i, _)| end + i);
    while !src.is_char_boundary(cut) {
        cut -= 1;
    }
    let rendered = render(name, &src[..cut], std::slice::from_ref(&d));
    LoadError::Model {
        file: name.to_string(),
        diagnostics: vec![d],
        rendered,
    }
}

fn model_error(name: &str, src: &str, diagnostics: Vec<Diagnostic>) -> LoadError {
    let rendered = render(name, src, &diagnostics);
    LoadError::Model {
        file: name.to_string(),
        diagnostics,
        rendered,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HybridModel;
    use proptest::prelude::*;

    const BALL: &str = include_str!("../../models/bouncing_ball.hyb");

    fn first_line(e: &LoadError) -> String {
        e.to_string().lines().next().unwrap_or_default().to_string()
    }

    #[test]
    fn loads_the_bouncing_ball() {
        let m = load_str("ball.hyb", BALL).expect("valid model");
        let info = m.info();
        assert_eq!(info.name, "BouncingBall");
        assert_eq!(info.params, ["e", "g", "h0", "v0"]);
        assert_eq!(info.states, ["h", "v"]);
        assert_eq!(info.observables, ["height", "velocity"]);
        assert_eq!(info.modes, ["main"]);
    }

    #[test]
    fn every_bundled_model_loads() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
        let mut count = 0;
        for entry in std::fs::read_dir(&dir).expect("models dir") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "hyb") {
                load(&path).unwrap_or_else(|e| panic!("{e}"));
                count += 1;
            }
        }
        assert!(count >= 6, "found {count} models");
    }

    #[test]
    fn empty_and_blank_files_are_located_errors() {
        for src in ["", "   \n\n  ", "\n"] {
            let e = load_str("e.hyb", src).map(|_| ()).expect_err("error");
            assert_eq!(
                first_line(&e),
                "e.hyb:1:1: error: empty model file; expected `model NAME { ... }`"
            );
        }
    }

    #[test]
    fn invalid_utf8_is_located() {
        let bytes = b"model M {\n  state x = 1;\xff\xfe\n}";
        let e = load_bytes("u.hyb", bytes).map(|_| ()).expect_err("error");
        let text = e.to_string();
        assert!(
            text.starts_with(
                "u.hyb:2:15: error: the file is not valid UTF-8 text (byte 0xFF at offset 24"
            ),
            "{text}"
        );
        assert!(text.contains("state x = 1;"), "{text}");
        assert!(text.contains('^'), "{text}");
    }

    #[test]
    fn binary_data_is_located() {
        let e = load_str("b.hyb", "model M {\n\u{0}\u{1}\u{2}")
            .map(|_| ())
            .expect_err("error");
        assert!(
            first_line(&e).starts_with("b.hyb:2:1: error: unexpected character U+0000"),
            "{e}"
        );
    }

    #[test]
    fn missing_file_and_directory_are_io_errors() {
        let e = load(Path::new("/nonexistent/model.hyb"))
            .map(|_| ())
            .expect_err("error");
        assert!(matches!(e, LoadError::Io { .. }));
        assert!(
            e.to_string()
                .starts_with("/nonexistent/model.hyb: error: cannot read file"),
            "{e}"
        );
        let e = load(Path::new("/dev/zero"))
            .map(|_| ())
            .expect_err("endless file");
        assert!(e.to_string().contains("larger than 16 MiB"), "{e}");
        let e = load(Path::new(env!("CARGO_MANIFEST_DIR")))
            .map(|_| ())
            .expect_err("error");
        assert!(e.to_string().ends_with("is a directory"), "{e}");
    }

    #[test]
    fn semantic_errors_are_rendered_with_the_line_and_a_caret() {
        let src = BALL.replace("der(v) = -g;", "der(v) = -gg;");
        let e = load_str("m.hyb", &src).map(|_| ()).expect_err("error");
        let text = e.to_string();
        let mut lines = text.lines();
        assert_eq!(
            lines.next(),
            Some("m.hyb:12:19: error: undefined name `gg`"),
            "{text}"
        );
        assert!(text.contains("der(v) = -gg;"), "{text}");
        let caret = text.lines().find(|l| l.contains('^')).expect("caret line");
        let col = caret.find('^').expect("caret");
        let quoted = text.lines().find(|l| l.contains("-gg;")).expect("quoted");
        assert_eq!(&quoted[col..col + 2], "gg", "{text}");
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let depth = 100_000;
        let src = format!(
            "model M {{ state x = {}1{}; flow {{ der(x) = 1; }} }}",
            "(".repeat(depth),
            ")".repeat(depth)
        );
        let e = load_str("deep.hyb", &src).map(|_| ()).expect_err("error");
        assert!(first_line(&e).starts_with("deep.hyb:1:"), "{e}");
        let src = format!(
            "model M {{ state x = {}1; flow {{ der(x) = 1; }} }}",
            "-".repeat(depth)
        );
        assert!(load_str("deep.hyb", &src).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, .. ProptestConfig::default() })]

        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
            let _ = load_bytes("fuzz.hyb", &bytes);
        }

        #[test]
        fn token_soups_never_panic(tokens in proptest::collection::vec(
            proptest::sample::select(vec![
                "model", "M", "{", "}", "(", ")", ";", "state", "param", "const", "flow", "mode",
                "der", "event", "when", "->", "<=", ">=", "<", ">", "=", "observe", "cost",
                "integral", "sum", "final", "horizon", "initial", "x", "y", "t", "1", "2.5", "1e-3",
                "+", "-", "*", "/", "^", ",", "if", "then", "else", "sin", "abs", "max", "pow",
                "//c\n", "/*", "*/", "\n",
            ]),
            0..80,
        )) {
            let src = tokens.join(" ");
            let _ = load_str("soup.hyb", &src);
        }

        #[test]
        fn mutated_models_never_panic(pos in 0usize..600, cut in 0usize..40, insert in "[ -~]{0,8}") {
            let mut src = BALL.to_string();
            let mut p = pos.min(src.len());
            while !src.is_char_boundary(p) { p -= 1; }
            let mut end = (p + cut).min(src.len());
            while !src.is_char_boundary(end) { end -= 1; }
            src.replace_range(p..end, &insert);
            let _ = load_str("mut.hyb", &src);
        }
    }
}
