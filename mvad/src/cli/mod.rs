//! The command line: argument parsing (clap), the options every command shares, and
//! the mapping of failures to exit statuses.
//!
//! Every command is a function generic over [`HybridModel`], so the same code serves a
//! model loaded from a `.hyb` file and a compiled (or hand-written) one. Commands build
//! their output in a `String`; only [`run`] prints.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use mvad::runtime::error::SolveError;
use mvad::runtime::solution::{GradientMode, Method, Solution};
use mvad::setup::{params_with, resolve, Request, Setup, SetupError, Spelling};
use mvad::table::TableSource;
use mvad::{HybridModel, ModelAlloc, ModelInfo};
use nalgebra::{Const, DefaultAllocator, OVector};

pub mod check;
pub mod fdcheck;
pub mod grad;
pub mod measure;
pub mod output;
pub mod plot;
pub mod progress;
pub mod qp_output;
pub mod report;
pub mod simulate;
#[cfg(test)]
pub mod spec_keys;
pub mod sweep;
pub mod workprec;

/// `mvad`: exact parameter derivatives of hybrid models, as measures.
#[derive(Parser, Debug)]
#[command(name = "mvad", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Parse and validate a model; print its states, params, modes, events and Jacobian sparsity.
    Check(check::CheckArgs),
    /// Simulate: the trajectory as CSV (to --out or stdout) and the table of events.
    Simulate(simulate::SimulateArgs),
    /// The cost C and its gradient dC/dθ, with the event table (times, slopes, atoms).
    Grad(grad::GradArgs),
    /// The derivative of one observable as a measure: density on a grid plus atoms.
    Measure(measure::MeasureArgs),
    /// MV-AD against central finite differences (the paper's Table 1).
    Fdcheck(fdcheck::FdcheckArgs),
    /// Vary one parameter over a range; event quantities per value (the paper's Table 2).
    Sweep(sweep::SweepArgs),
    /// Error against wall time over tolerances 1e-3 … 1e-12, for MV-AD and central FD.
    Workprec(workprec::WorkprecArgs),
    /// Run a suite of cases across methods and tolerances: a markdown table and diagrams.
    Report(report::ReportArgs),
}

/// Options every command takes.
#[derive(Args, Debug, Clone)]
pub struct Common {
    /// The model file (`.hyb`).
    pub model: PathBuf,
    /// Override a parameter (repeatable): `--set e=0.5`.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
    /// Final time T, overriding the model's horizon (then dT/dθ = 0).
    #[arg(long = "t-end", value_name = "T", allow_negative_numbers = true)]
    pub t_end: Option<f64>,
    /// Parameters to differentiate with respect to, comma separated (default: all).
    #[arg(long, value_name = "A,B,..")]
    pub wrt: Option<String>,
    /// Relative tolerance of the integrator.
    #[arg(long, allow_negative_numbers = true)]
    pub rtol: Option<f64>,
    /// Absolute tolerance of the integrator.
    #[arg(long, allow_negative_numbers = true)]
    pub atol: Option<f64>,
    /// Integration method (`auto` copes with stiff models by itself).
    #[arg(long, default_value = "auto", value_parser = ["auto", "tsit5", "verner9", "rosenbrock"])]
    pub method: String,
    /// τ of the grazing test |∇ₓg·f| < τ |∇ₓg| |f|.
    #[arg(
        long = "grazing-tol",
        value_name = "TAU",
        allow_negative_numbers = true
    )]
    pub grazing_tol: Option<f64>,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Read data table NAME from FILE instead of the file the model names (repeatable).
    #[arg(long = "table", value_name = "NAME=FILE")]
    pub table: Vec<String>,
    /// List every event in the JSON output (by default the first 1000; `stats.events`
    /// always counts all of them).
    #[arg(long = "all-events")]
    pub all_events: bool,
}

impl Common {
    /// The `--table NAME=FILE` replacements; a NAME given twice is an error (which file
    /// would the run read?).
    pub fn tables(&self) -> Result<Vec<(String, TableSource)>, CliError> {
        let mut out: Vec<(String, TableSource)> = Vec::with_capacity(self.table.len());
        for item in &self.table {
            let (name, file) = match item.split_once('=') {
                Some((name, file)) if !name.trim().is_empty() && !file.trim().is_empty() => {
                    (name.trim(), file.trim())
                }
                _ => {
                    return Err(CliError::Input(format!(
                        "error: --table expects NAME=FILE, got `{item}`"
                    )))
                }
            };
            if out.iter().any(|(n, _)| n == name) {
                return Err(CliError::Input(format!(
                    "error: --table names table `{name}` twice; give each table once"
                )));
            }
            out.push((name.to_string(), TableSource::File(PathBuf::from(file))));
        }
        Ok(out)
    }

    /// How many events the JSON output lists.
    pub fn event_limit(&self) -> usize {
        if self.all_events {
            usize::MAX
        } else {
            mvad::json::MAX_JSON_EVENTS
        }
    }
}

/// Why a command did not succeed, with the exit status it maps to.
#[derive(Debug, Clone, PartialEq)]
pub enum CliError {
    /// Bad input (a model error, already rendered; a bad option): exit status 2.
    Input(String),
    /// The model ran and failed: exit status 1.
    Run(String),
}

impl CliError {
    /// The exit status of this failure.
    pub fn status(&self) -> u8 {
        match self {
            CliError::Input(_) => 2,
            CliError::Run(_) => 1,
        }
    }
    /// The message (for stderr, and the `"error"` key under `--json`).
    pub fn message(&self) -> &str {
        match self {
            CliError::Input(m) | CliError::Run(m) => m,
        }
    }
    /// The same kind of failure (and exit status) with the message `f` makes of it.
    pub fn map_message(self, f: impl FnOnce(&str) -> String) -> Self {
        match self {
            CliError::Input(m) => CliError::Input(f(&m)),
            CliError::Run(m) => CliError::Run(f(&m)),
        }
    }
}

/// What a command produced: text for stdout.
pub type CmdResult = Result<String, CliError>;

/// Parses `args` and runs the command; never panics on any input.
///
/// `load` turns the model path and the `--table` replacements into a model, or into the
/// rendered error (exit 2).
pub fn run<I, M, L>(args: I, load: L) -> ExitCode
where
    I: IntoIterator<Item = OsString>,
    M: HybridModel + Clone + Send,
    DefaultAllocator: ModelAlloc<M::N, M::P>,
    L: FnOnce(&Path, &[(String, TableSource)]) -> Result<M, String>,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(err) => {
            use clap::error::ErrorKind;
            // --help and --version are successes; every other clap error is a usage error (2).
            let status = match err.kind() {
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => 0,
                _ => 2,
            };
            let text = err.render().to_string();
            if status == 0 {
                write_stdout(&text);
            } else {
                write_stderr(&text);
            }
            return ExitCode::from(status);
        }
    };
    let json = cli.common().is_some_and(|c| c.json);
    match dispatch(&cli, load) {
        Ok(out) => {
            if write_stdout(&out) {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            }
        }
        Err(err) => {
            let msg = err.message();
            let mut text = msg.to_string();
            if !text.ends_with('\n') {
                text.push('\n');
            }
            write_stderr(&text);
            if json {
                let kind = if err.status() == 2 { "input" } else { "run" };
                let obj = serde_json::json!({ "error": msg.trim_end(), "kind": kind });
                write_stdout(&format!("{obj}\n"));
            }
            ExitCode::from(err.status())
        }
    }
}

impl Cli {
    /// The common options of whichever command was given (`report` runs a suite, not one
    /// model, and has none).
    pub fn common(&self) -> Option<&Common> {
        match &self.command {
            Command::Check(a) => Some(&a.common),
            Command::Simulate(a) => Some(&a.common),
            Command::Grad(a) => Some(&a.common),
            Command::Measure(a) => Some(&a.common),
            Command::Fdcheck(a) => Some(&a.common),
            Command::Sweep(a) => Some(&a.common),
            Command::Workprec(a) => Some(&a.common),
            Command::Report(_) => None,
        }
    }
}

/// Runs the parsed command on the model `load` returns for the model path.
fn dispatch<M, L>(cli: &Cli, load: L) -> CmdResult
where
    M: HybridModel + Clone + Send,
    DefaultAllocator: ModelAlloc<M::N, M::P>,
    L: FnOnce(&Path, &[(String, TableSource)]) -> Result<M, String>,
{
    let Some(common) = cli.common() else {
        return match &cli.command {
            Command::Report(a) => report::run(a),
            _ => Err(CliError::Input("error: no model given".into())),
        };
    };
    let tables = common.tables()?;
    let model = load(&common.model, &tables).map_err(CliError::Input)?;
    let file = common.model.display().to_string();
    match &cli.command {
        Command::Check(a) => check::run(&model, &file, a),
        Command::Simulate(a) => simulate::run(&model, &file, a),
        Command::Grad(a) => grad::run(&model, &file, a),
        Command::Measure(a) => measure::run(&model, &file, a),
        Command::Fdcheck(a) => fdcheck::run(&model, &file, a),
        Command::Sweep(a) => sweep::run(&model, &file, a),
        Command::Workprec(a) => workprec::run(&model, &file, a),
        Command::Report(a) => report::run(a),
    }
}

/// Writes to stdout; false if that failed (a closed pipe is not a panic).
fn write_stdout(text: &str) -> bool {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|_| out.flush())
        .is_ok()
}

/// Writes to stderr, ignoring failures.
pub fn write_stderr(text: &str) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_all(text.as_bytes());
    let _ = err.flush();
}

/// Parses a finite number.
pub fn parse_number(text: &str, what: &str) -> Result<f64, CliError> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(CliError::Input(format!(
            "{what}: `{text}` is not a finite number"
        ))),
        Err(_) => Err(CliError::Input(format!("{what}: `{text}` is not a number"))),
    }
}

/// How the command line spells an option: `--t-end`, `--t-end T`; an option given already
/// spelled (`--over`) is kept as it is.
pub struct Flags;

impl Spelling for Flags {
    fn option(&self, name: &str) -> String {
        if name.starts_with("--") {
            name.to_string()
        } else {
            format!("--{}", name.replace('_', "-"))
        }
    }
    fn assign(&self, name: &str, value: &str) -> String {
        format!("{} {value}", self.option(name))
    }
}

/// A request that cannot run, as bad input (exit status 2) in the command line's words.
pub fn setup_err(e: SetupError) -> CliError {
    CliError::Input(format!("error: {}", e.message(&Flags)))
}

/// Index of parameter `name`, or a bad-input error listing the known ones.
pub fn param_index(names: &[String], name: &str, option: &'static str) -> Result<usize, CliError> {
    mvad::setup::param_index(names, name, option).map_err(setup_err)
}

/// Resolves the common options against a model (`mvad::setup::resolve`).
pub fn setup<M: HybridModel>(model: &M, common: &Common) -> Result<Setup<M>, CliError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let req = Request {
        set: parse_set(common)?,
        wrt: common
            .wrt
            .as_deref()
            .map(|list| list.split(',').map(String::from).collect()),
        t_end: common.t_end,
        rtol: common.rtol,
        atol: common.atol,
        method: Method::from_name(&common.method).unwrap_or_default(),
        grazing_tol: common.grazing_tol,
        tables: common.tables()?,
        // `grad` sets its own `--mode`; every other command is forward mode's.
        mode: GradientMode::Forward,
    };
    resolve(model, &req).map_err(setup_err)
}

/// The `--set NAME=VALUE` items as (name, value) pairs.
fn parse_set(common: &Common) -> Result<Vec<(String, f64)>, CliError> {
    common
        .set
        .iter()
        .map(|item| {
            let Some((name, value)) = item.split_once('=') else {
                return Err(CliError::Input(format!(
                    "error: --set expects NAME=VALUE, got `{item}`"
                )));
            };
            let name = name.trim();
            let value = parse_number(value, &format!("error: --set {name}"))?;
            Ok((name.to_string(), value))
        })
        .collect()
}

/// θ: the declared parameter values with every `--set NAME=VALUE` applied.
pub fn setup_params_only<M: HybridModel>(
    model: &M,
    common: &Common,
) -> Result<OVector<f64, M::P>, CliError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    params_with(model, &parse_set(common)?).map_err(setup_err)
}

/// Index of observable `name`, or a bad-input error listing the known ones.
pub fn observable_index(info: &ModelInfo, name: &str) -> Result<usize, CliError> {
    info.observable_index(name).ok_or_else(|| {
        CliError::Input(format!(
            "error: unknown observable `{name}`; {}",
            if info.observables.is_empty() {
                "the model declares no observables".to_string()
            } else {
                format!("known observables: {}", info.observables.join(", "))
            }
        ))
    })
}

/// Checks the relative step h of central differences: 0 < h < 1.
pub fn check_step(step: f64) -> Result<(), CliError> {
    if step.is_finite() && step > 0.0 && step < 1.0 {
        Ok(())
    } else {
        Err(CliError::Input(format!(
            "error: --step must be in (0, 1), got {}",
            mvad_runtime::error::Time(step)
        )))
    }
}

/// Solves at the setup's parameters, keeping the first `common.event_limit()` events only
/// (`mvad::json::solve_listing`).
pub fn solve_listing<M: HybridModel>(
    model: &M,
    s: &Setup<M>,
    common: &Common,
) -> Result<Solution, CliError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    mvad::json::solve_listing(model, &s.params, &s.opts, common.event_limit()).map_err(solve_err)
}

/// Maps a runtime failure to an exit status: bad input (options, parameters, horizon)
/// is 2, a model that ran and failed (non-finite values, step size underflow, too many
/// events) is 1. The runtime's messages name no flags; the hints naming this CLI's flags
/// are added here, in one place.
pub fn solve_err(e: SolveError) -> CliError {
    let hint = match &e {
        SolveError::NoHorizon => "; give one with --t-end",
        SolveError::MaxSteps {
            not_stiff: false, ..
        } => " (--method auto or --method rosenbrock)",
        _ => "",
    };
    if e.is_bad_input() {
        CliError::Input(format!("error: {e}{hint}"))
    } else {
        CliError::Run(format!("error: the run failed: {e}{hint}"))
    }
}

/// A vector of the model's state dimension from a slice.
pub fn xvec<M: HybridModel>(model: &M, values: &[f64]) -> OVector<f64, M::N>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    OVector::<f64, M::N>::from_iterator_generic(model.nstates(), Const::<1>, values.iter().copied())
}

/// Helpers the commands' unit tests share.
#[cfg(test)]
pub mod test_support {
    use super::*;
    use mvad::runtime::fixtures::Ball;
    use serde_json::Value;

    /// Asserts that `out` contains each of `parts` (the message shows the part and `out`).
    #[track_caller]
    pub fn assert_contains_all(out: &str, parts: &[&str]) {
        for part in parts {
            assert!(out.contains(part), "{part:?} missing from:\n{out}");
        }
    }

    /// Tolerances at which the E1 ball is accurate to about 1e-10.
    pub const TIGHT: [&str; 4] = ["--rtol", "1e-10", "--atol", "1e-12"];

    /// The arguments of one command, picked out of a parsed command line.
    pub trait CommandArgs: Sized {
        /// The command's name on the command line.
        const NAME: &'static str;
        /// These arguments, if `cmd` is this command.
        fn pick(cmd: Command) -> Option<Self>;
    }

    macro_rules! command_args {
        ($($ty:ty => $variant:ident, $name:literal;)*) => {$(
            impl CommandArgs for $ty {
                const NAME: &'static str = $name;
                fn pick(cmd: Command) -> Option<Self> {
                    match cmd {
                        Command::$variant(a) => Some(a),
                        _ => None,
                    }
                }
            }
        )*};
    }

    command_args! {
        check::CheckArgs => Check, "check";
        simulate::SimulateArgs => Simulate, "simulate";
        grad::GradArgs => Grad, "grad";
        measure::MeasureArgs => Measure, "measure";
        fdcheck::FdcheckArgs => Fdcheck, "fdcheck";
        sweep::SweepArgs => Sweep, "sweep";
        workprec::WorkprecArgs => Workprec, "workprec";
    }

    /// `mvad NAME ball.hyb EXTRA…` parsed into the arguments of command NAME.
    pub fn args<A: CommandArgs>(extra: &[&str]) -> A {
        let mut words = vec!["mvad", A::NAME, "ball.hyb"];
        words.extend_from_slice(extra);
        let cli = Cli::try_parse_from(words).expect("the arguments parse");
        A::pick(cli.command).expect("the command asked for")
    }

    /// Runs a command's `run` on the hand-written E1 ball (`fixtures::Ball`, file name
    /// `ball.hyb`) with the arguments `extra`.
    pub fn on_ball<A: CommandArgs>(
        run: impl Fn(&Ball, &str, &A) -> CmdResult,
        extra: &[&str],
    ) -> CmdResult {
        run(&Ball::new(), "ball.hyb", &args(extra))
    }

    /// `extra` followed by [`TIGHT`].
    pub fn tight<'a>(extra: &[&'a str]) -> Vec<&'a str> {
        extra.iter().copied().chain(TIGHT).collect()
    }

    /// How many lines of a command's output contain `needle`.
    pub fn lines_with(out: &str, needle: &str) -> usize {
        out.lines().filter(|l| l.contains(needle)).count()
    }

    /// The JSON object a command printed.
    pub fn json(out: &str) -> Value {
        serde_json::from_str(out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
    }

    /// A scratch directory for the files of the test named `tag`, removed when dropped.
    pub fn scratch_dir(tag: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("mvad-{tag}-"))
            .tempdir()
            .expect("a scratch directory")
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::args;
    use super::*;
    use clap::CommandFactory;
    use mvad::runtime::fixtures::Ball;

    fn common(extra: &[&str]) -> Common {
        args::<check::CheckArgs>(extra).common
    }

    #[test]
    fn clap_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn set_overrides_and_unknown_lists_known() {
        let ball = Ball::new();
        let s = setup(&ball, &common(&["--set", "e=0.5", "--set", "h0 = 3"])).expect("ok");
        assert_eq!(s.params.as_slice(), &[0.5, 9.81, 3.0, 0.0]);
        let err = setup(&ball, &common(&["--set", "q=1"]))
            .err()
            .expect("unknown param");
        assert_eq!(err.status(), 2);
        assert!(
            err.message().contains("known parameters: e, g, h0, v0"),
            "{err:?}"
        );
        for bad in ["e", "e=abc", "e=nan", "e=inf"] {
            let err = setup(&ball, &common(&["--set", bad])).err().expect(bad);
            assert_eq!(err.status(), 2, "{bad}");
        }
    }

    #[test]
    fn wrt_and_tolerances() {
        let ball = Ball::new();
        let s = setup(&ball, &common(&["--wrt", "v0,e,v0", "--rtol", "1e-6"])).expect("ok");
        assert_eq!(s.wrt, vec![3, 0]);
        assert_eq!(s.opts.rtol, 1e-6);
        for bad in [
            &["--wrt", "x"][..],
            &["--wrt", ","],
            &["--rtol", "0"],
            &["--rtol", "-1"],
            &["--atol", "inf"],
            &["--t-end", "-2"],
            &["--grazing-tol", "2"],
        ] {
            let err = setup(&ball, &common(bad)).err().expect("bad option");
            assert_eq!(err.status(), 2, "{bad:?}");
        }
        let s = setup(&ball, &common(&["--t-end", "3.5", "--method", "verner9"])).expect("ok");
        assert_eq!(s.opts.t_end, Some(3.5));
        assert_eq!(s.opts.method, Method::Verner9);
    }
}
