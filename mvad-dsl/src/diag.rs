//! Located errors: [`Diagnostic`], the renaming of pest rules to phrases, the text
//! renderer (`FILE:LINE:COL: error: MESSAGE`, the quoted line, carets) and
//! [`to_syn_error`] for the macro.

use crate::span::Span;

/// A located error in a model.
///
/// Messages are lowercase, without a trailing period, and quote names with backticks:
/// "undefined name `vv`".
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// The offending text (the caret goes under it).
    pub span: Span,
    /// The main message.
    pub message: String,
    /// Secondary locations with a note each ("first declared here").
    pub labels: Vec<(Span, String)>,
    /// An optional hint ("add `der(v) = ...;`").
    pub help: Option<String>,
}

impl Diagnostic {
    /// An error at `span` with `message`, no labels, no help.
    pub fn new(span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            span,
            message: message.into(),
            labels: Vec::new(),
            help: None,
        }
    }

    /// Adds a secondary location with a note.
    pub fn with_label(mut self, span: Span, note: impl Into<String>) -> Diagnostic {
        self.labels.push((span, note.into()));
        self
    }

    /// Adds a hint.
    pub fn with_help(mut self, help: impl Into<String>) -> Diagnostic {
        self.help = Some(help.into());
        self
    }
}

impl std::fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Diagnostic {}

use crate::parse::Rule;

/// The phrase used for `rule` in "expected ..." lists.
pub fn rule_phrase(rule: Rule) -> &'static str {
    match rule {
        Rule::EOI => "end of input",
        Rule::WHITESPACE | Rule::COMMENT => "a blank",
        Rule::ident | Rule::structural_keyword => "an identifier",
        Rule::number => "a number",
        Rule::expr | Rule::paren | Rule::call | Rule::if_expr => "an expression",
        Rule::condition => "a comparison",
        Rule::kw_model | Rule::model | Rule::file => "`model`",
        Rule::kw_param | Rule::param_decl => "`param`",
        Rule::kw_const | Rule::const_decl => "`const`",
        Rule::kw_state | Rule::state_decl => "`state`",
        Rule::kw_flow | Rule::flow_block => "`flow`",
        Rule::kw_mode | Rule::mode_block => "`mode`",
        Rule::kw_initial | Rule::initial_decl => "`initial`",
        Rule::kw_event | Rule::event_decl => "`event`",
        Rule::kw_when | Rule::when_trigger => "`when`",
        Rule::kw_at | Rule::at_trigger | Rule::each_trigger => "`at`",
        Rule::kw_each => "`each`",
        Rule::kw_every | Rule::every_trigger => "`every`",
        Rule::kw_from => "`from`",
        Rule::trigger => "`when`, `at` or `every`",
        Rule::kw_table | Rule::table_decl => "`table`",
        Rule::string => "a file name in quotes",
        Rule::dot => "`.`",
        Rule::column => "a dotted name (`TABLE.COL` or `QP.VAR`)",
        Rule::kw_observe | Rule::observe_decl => "`observe`",
        Rule::kw_cost | Rule::cost_decl => "`cost`",
        Rule::kw_horizon | Rule::horizon_decl => "`horizon`",
        Rule::kw_der | Rule::der_eq => "`der`",
        Rule::kw_integral | Rule::integral_term => "`integral`",
        Rule::kw_sum | Rule::sum_term => "`sum`",
        Rule::kw_final | Rule::final_term => "`final`",
        Rule::cost_term | Rule::static_term => {
            "a cost term (`integral`, `sum`, `final` or a static expression)"
        }
        Rule::kw_qp | Rule::qp_decl => "`qp`",
        Rule::kw_minimize | Rule::qp_objective => "`minimize`",
        Rule::kw_subject | Rule::qp_constraints => "`subject to`",
        Rule::kw_to => "`to`",
        Rule::qp_constraint => "a constraint",
        Rule::eq => "`==`",
        Rule::kw_if => "`if`",
        Rule::kw_then => "`then`",
        Rule::kw_else => "`else`",
        Rule::semicolon => "`;`",
        Rule::comma => "`,`",
        Rule::lbrace | Rule::reset_block => "`{`",
        Rule::rbrace => "`}`",
        Rule::lparen => "`(`",
        Rule::rparen => "`)`",
        Rule::assign => "`=`",
        Rule::arrow | Rule::target => "`->`",
        Rule::add => "`+`",
        Rule::sub | Rule::neg => "`-`",
        Rule::mul => "`*`",
        Rule::div => "`/`",
        Rule::pow => "`^`",
        Rule::le => "`<=`",
        Rule::lt => "`<`",
        Rule::ge => "`>=`",
        Rule::gt => "`>`",
        Rule::reset => "an assignment",
        Rule::ident_char => "an identifier character",
        Rule::digits => "a digit",
        Rule::cmp_op => "a comparison operator",
        Rule::infix => "an operator",
        Rule::primary => "an expression",
        Rule::item => "a declaration",
    }
}

/// Describes the text at byte `pos` of `src` for "unexpected ..." messages: a whole word,
/// number or operator in backticks, a control character by code point, or "end of input".
pub fn describe_at(src: &str, pos: usize) -> String {
    let mut pos = pos.min(src.len());
    while !src.is_char_boundary(pos) {
        pos -= 1;
    }
    let rest = &src[pos..];
    let Some(c) = rest.chars().next() else {
        return "end of input".to_string();
    };
    if c.is_alphanumeric() || c == '_' {
        let word: String = rest
            .chars()
            .take_while(|&c| c.is_alphanumeric() || c == '_' || c == '.')
            .take(40)
            .collect();
        return format!("`{word}`");
    }
    for op in ["<=", ">=", "->", "==", "!=", "&&", "||", "::"] {
        if rest.starts_with(op) {
            return format!("`{op}`");
        }
    }
    if c.is_control() || c == '`' || c == '\u{FFFD}' {
        return format!("character U+{:04X}", c as u32);
    }
    format!("`{c}`")
}

/// Joins phrases as "A", "A or B", "A, B, or C".
fn one_of(items: &[&str]) -> String {
    match items {
        [] => String::new(),
        [a] => a.to_string(),
        [a, b] => format!("{a} or {b}"),
        [init @ .., last] => format!("{}, or {last}", init.join(", ")),
    }
}

/// Converts a pest error into a [`Diagnostic`]: "unexpected X; expected A, B, or C", with
/// pest's rule names renamed to phrases ([`rule_phrase`]).
pub fn from_pest(err: &pest::error::Error<Rule>, src: &str) -> Diagnostic {
    use pest::error::{ErrorVariant, InputLocation};
    let (start, end) = match err.location {
        InputLocation::Pos(p) => (p, p),
        InputLocation::Span((a, b)) => (a, b),
    };
    let unexpected = describe_at(src, start);
    let message = match &err.variant {
        _ if src.get(start..).is_some_and(|r| r.starts_with("/*")) => {
            "unterminated block comment".to_string()
        }
        ErrorVariant::ParsingError { positives, .. } => {
            // Where an operand may start, pest lists every way to start one: say "an
            // expression" instead.
            let operand_start = positives.contains(&Rule::number);
            let mut phrases: Vec<&str> = Vec::new();
            for r in positives {
                let p = match r {
                    Rule::ident
                    | Rule::number
                    | Rule::kw_if
                    | Rule::lparen
                    | Rule::neg
                    | Rule::if_expr
                    | Rule::call
                    | Rule::paren
                    | Rule::column
                        if operand_start =>
                    {
                        "an expression"
                    }
                    _ => rule_phrase(*r),
                };
                if !phrases.contains(&p) {
                    phrases.push(p);
                }
            }
            if phrases.is_empty() {
                format!("unexpected {unexpected}")
            } else {
                format!("unexpected {unexpected}; expected {}", one_of(&phrases))
            }
        }
        ErrorVariant::CustomError { message } => message.clone(),
    };
    // Point at the whole offending token (at least one character), not an empty range.
    let token_len = token_len_at(src, start);
    let span = Span::new(start, end.max(start + token_len));
    let mut diag = Diagnostic::new(span, message);
    // A missing `;` at the end of a line is reported at the next line's first token;
    // say where the `;` probably belongs.
    if let ErrorVariant::ParsingError { positives, .. } = &err.variant {
        if positives.contains(&Rule::semicolon) {
            if let Some(prev) = previous_token_on_earlier_line(src, start) {
                let text = &src[prev.range()];
                diag = diag
                    .with_label(prev, "`;` may be missing here")
                    .with_help(format!("add `;` after `{text}`"));
            }
        }
    }
    diag
}

/// The token just before byte `pos` if only blanks (with at least one line break)
/// separate them; `None` if there is a comment in between or nothing before.
fn previous_token_on_earlier_line(src: &str, pos: usize) -> Option<Span> {
    let before = src.get(..pos)?;
    let trimmed = before.trim_end();
    if !before[trimmed.len()..].contains('\n') || trimmed.is_empty() {
        return None;
    }
    let end = trimmed.len();
    let last = trimmed.chars().next_back()?;
    let word = |c: char| c.is_alphanumeric() || c == '_' || c == '.';
    let start = if word(last) {
        trimmed
            .char_indices()
            .rev()
            .take_while(|&(_, c)| word(c))
            .last()
            .map_or(end, |(i, _)| i)
    } else {
        end - last.len_utf8()
    };
    // A line comment on that line would make the "last token" part of the comment.
    let line_start = trimmed[..start].rfind('\n').map_or(0, |i| i + 1);
    if trimmed[line_start..].contains("//") || trimmed[line_start..].contains("*/") {
        return None;
    }
    Some(Span::new(start, end))
}

/// Byte length of the token starting at `pos` (a word, a two-character operator or one
/// character; 0 at the end of input).
fn token_len_at(src: &str, pos: usize) -> usize {
    if pos >= src.len() || !src.is_char_boundary(pos) {
        return 0;
    }
    let rest = &src[pos..];
    let number = rest.starts_with(|c: char| c.is_ascii_digit());
    let word: usize = rest
        .char_indices()
        .take_while(|&(_, c)| c.is_alphanumeric() || c == '_' || (number && c == '.'))
        .map(|(i, c)| i + c.len_utf8())
        .last()
        .unwrap_or(0);
    if word > 0 {
        return word;
    }
    for op in ["<=", ">=", "->", "==", "!="] {
        if rest.starts_with(op) {
            return 2;
        }
    }
    rest.chars().next().map_or(0, char::len_utf8)
}

/// Renders `diags` for a terminal: for each, the line `FILE:LINE:COL: error: MESSAGE`
/// (1-based line and column of the span's start), the offending source line quoted with
/// `^` carets under the span and each label's line with `-` under its span and the note
/// (all in source order), and
/// `= help: ...` if there is a hint. Diagnostics are separated by a blank line.
pub fn render(file_name: &str, src: &str, diags: &[Diagnostic]) -> String {
    let file = crate::span::SourceFile::new(file_name, src);
    let mut out = String::new();
    for (k, d) in diags.iter().enumerate() {
        if k > 0 {
            out.push('\n');
        }
        let (line, col) = file.line_col(d.span.start);
        out.push_str(&format!("{file_name}:{line}:{col}: error: {}\n", d.message));
        let mut snippets: Vec<(Span, char, Option<&str>)> = vec![(d.span, '^', None)];
        snippets.extend(d.labels.iter().map(|(s, n)| (*s, '-', Some(n.as_str()))));
        // In source order, as rustc shows them (the sort is stable: the primary span
        // stays first among equals).
        snippets.sort_by_key(|(s, _, _)| s.start);
        let width = snippets
            .iter()
            .map(|(s, _, _)| file.line_col(s.start).0.to_string().len())
            .max()
            .unwrap_or(1);
        let gutter = " ".repeat(width);
        out.push_str(&format!("{gutter} |\n"));
        // The line shown last, and the window of its characters that was shown.
        let mut shown: Option<(usize, Window)> = None;
        for (span, mark, note) in snippets {
            let (l, c) = file.line_col(span.start);
            // Control characters would garble the terminal: show them as U+FFFD.
            let text: Vec<char> = file
                .line_text(l)
                .chars()
                .map(|ch| {
                    if ch.is_control() && ch != '\t' {
                        '\u{FFFD}'
                    } else {
                        ch
                    }
                })
                .collect();
            let window = match shown {
                Some((sl, w)) if sl == l => w,
                _ => {
                    let w = Window::around(text.len(), c - 1);
                    out.push_str(&format!("{l:>width$} | {}\n", w.show(&text)));
                    shown = Some((l, w));
                    w
                }
            };
            let (end_line, end_col) = file.line_col(span.end);
            let end = if end_line == l {
                end_col - 1
            } else {
                text.len()
            };
            let (prefix, len) = window.marks(&text, c - 1, end);
            let marks = mark.to_string().repeat(len.max(1));
            match note {
                Some(n) => out.push_str(&format!("{gutter} | {prefix}{marks} {n}\n")),
                None => out.push_str(&format!("{gutter} | {prefix}{marks}\n")),
            }
        }
        if let Some(h) = &d.help {
            out.push_str(&format!("{gutter} = help: {h}\n"));
        }
    }
    out
}

/// The part of a long source line that is quoted: characters `start..end`, with `...`
/// marking what was cut on either side.
#[derive(Clone, Copy)]
struct Window {
    start: usize,
    end: usize,
    len: usize,
}

impl Window {
    /// Lines up to this many characters are quoted whole.
    const MAX: usize = 120;

    /// A window of a line of `len` characters that shows column `col` (0-based).
    fn around(len: usize, col: usize) -> Window {
        if len <= Self::MAX {
            return Window {
                start: 0,
                end: len,
                len,
            };
        }
        let start = col.saturating_sub(Self::MAX / 2).min(len - Self::MAX);
        Window {
            start,
            end: start + Self::MAX,
            len,
        }
    }

    fn show(self, text: &[char]) -> String {
        let mut s = String::new();
        if self.start > 0 {
            s.push_str("...");
        }
        s.extend(&text[self.start..self.end]);
        if self.end < self.len {
            s.push_str("...");
        }
        s
    }

    /// The blank prefix (tabs kept so marks align) up to column `from`, and the number of
    /// marks for columns `from..to`, both clipped to the window.
    fn marks(self, text: &[char], from: usize, to: usize) -> (String, usize) {
        let from = from.clamp(self.start, self.end);
        let to = to.clamp(from, self.end);
        let mut prefix = String::new();
        if self.start > 0 {
            prefix.push_str("   ");
        }
        prefix.extend(
            text[self.start..from]
                .iter()
                .map(|&ch| if ch == '\t' { '\t' } else { ' ' }),
        );
        (prefix, to - from)
    }
}

/// Converts `d` into a `syn::Error` spanning the user's tokens that produced `d.span`
/// (first to last token, via `map`), so rustc underlines them. The help, if any, follows
/// the message on its own line. Secondary labels are dropped (a macro error has one span).
pub fn to_syn_error(d: &Diagnostic, map: &crate::tokens::SourceMap) -> syn::Error {
    let message = match &d.help {
        Some(h) => format!("{}\n\nhelp: {h}", d.message),
        None => d.message.clone(),
    };
    match map.lookup(d.span) {
        Some((first, last)) => {
            let mut tokens = proc_macro2::TokenStream::new();
            tokens.extend([
                proc_macro2::TokenTree::Ident(proc_macro2::Ident::new("first", first)),
                proc_macro2::TokenTree::Ident(proc_macro2::Ident::new("last", last)),
            ]);
            syn::Error::new_spanned(tokens, message)
        }
        None => syn::Error::new(proc_macro2::Span::call_site(), message),
    }
}
