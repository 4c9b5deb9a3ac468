//! The data tables of a loaded model and its time events: which columns the kernels read
//! ([`mvad_dsl::ir::Node::Column`] c is entry c of the row), the values bound to them, the
//! current row handed to the methods of an `at each` event, and the times τ_kj(θ) of time
//! events with their gradients.

use std::cell::{Cell, Ref, RefCell};

use mvad_dsl::eval::Tape;
use mvad_dsl::schedule::ModelKernels;
use mvad_runtime::Trigger;

use super::run::{pt_theta, TapeAt};
use super::{InterpretedModel, Scratch, X};
use crate::table::{bind_columns, Table, TableError, TableNeeds};

/// τ (or the start of `every`), ∂τ/∂θ, and for `every` the period and its gradient.
pub(super) type TimeTapes = (Tape, Tape, Option<(Tape, Tape)>);

/// The data tables of a model: its declarations and the columns it reads, bound to data.
#[derive(Clone, Debug, Default)]
pub(super) struct Tables {
    /// Declared (name, file).
    decls: Vec<(String, String)>,
    /// Columns read: (table, column name).
    names: Vec<(usize, String)>,
    /// Columns used bare as the times of an `at each` event: (column, event name).
    times: Vec<(usize, String)>,
    /// Per event: the table an `at each` event runs over.
    each: Vec<Option<usize>>,
    /// The bound values of each column (empty until [`InterpretedModel::bind_tables`]).
    values: Vec<std::sync::Arc<Vec<f64>>>,
    /// The current row's values of every column (scratch of the event methods).
    row: RefCell<Vec<f64>>,
    /// The (event, row) `row` holds (the methods of one event read the same row in turn).
    filled: Cell<Option<(usize, usize)>>,
}

impl Tables {
    pub(super) fn new(k: &ModelKernels) -> Tables {
        Tables {
            decls: k.names.tables.clone(),
            names: k.names.columns.clone(),
            times: k
                .bare_time_columns()
                .into_iter()
                .map(|(c, e)| (c, k.event_meta[e].info.name.clone()))
                .collect(),
            each: k.event_meta.iter().map(|m| m.table).collect(),
            values: Vec::new(),
            row: RefCell::new(vec![f64::NAN; k.names.columns.len()]),
            filled: Cell::new(None),
        }
    }

    /// Row `j` of the table of event `event`: every column of that table at row j, NaN in the
    /// columns of other tables (and for any other event).
    pub(super) fn row(&self, event: usize, j: usize) -> Ref<'_, Vec<f64>> {
        if self.filled.get() != Some((event, j)) {
            self.filled.set(Some((event, j)));
            let mut row = self.row.borrow_mut();
            let table = self.each.get(event).copied().flatten();
            for (c, v) in row.iter_mut().enumerate() {
                *v = match (table, self.names.get(c), self.values.get(c)) {
                    (Some(t), Some((ct, _)), Some(col)) if *ct == t => {
                        col.get(j).copied().unwrap_or(f64::NAN)
                    }
                    _ => f64::NAN,
                };
            }
        }
        self.row.borrow()
    }
}

impl InterpretedModel {
    /// The declared tables: (name, file as written in the model).
    pub fn table_decls(&self) -> &[(String, String)] {
        &self.tables.decls
    }

    /// Binds the model's data: one table per declaration, in declaration order. Checks that
    /// the columns the model reads exist and that bare `at each` times do not decrease (errors
    /// located in the table's file), and sets the row counts of the `at each` events.
    pub fn bind_tables(&mut self, tables: &[&Table]) -> Result<(), TableError> {
        let t = &self.tables;
        let needs = TableNeeds {
            tables: t.decls.iter().map(|(n, _)| n.as_str()).collect(),
            columns: t.names.iter().map(|(i, c)| (*i, c.as_str())).collect(),
            times: t.times.iter().map(|(c, e)| (*c, e.as_str())).collect(),
        };
        let (values, rows) = bind_columns(&needs, tables)?;
        for (info, each) in self.info.events.iter_mut().zip(&self.tables.each) {
            if let Some(table) = each {
                info.trigger = Trigger::Each {
                    rows: rows.get(*table).copied().unwrap_or(0),
                };
            }
        }
        self.tables.values = values;
        self.tables.filled.set(None);
        Ok(())
    }

    /// τ_kj(θ): the time of occurrence j of time event k (NaN for a state event).
    pub(super) fn time_of(&self, event: usize, j: usize, p: &X) -> f64 {
        let Some((tau, _, period)) = self.events.get(event).and_then(|e| e.time.as_ref()) else {
            return f64::NAN;
        };
        let row = self.tables.row(event, j);
        let at = TapeAt {
            row: &row,
            ..pt_theta(p)
        };
        let first = self.scalar(tau, &at);
        match period {
            Some((per, _)) => first + j as f64 * self.scalar(per, &at),
            None => first,
        }
    }

    /// ∂τ_kj/∂θ into `dtau` (NaN for a state event): ∂start/∂θ + j·∂period/∂θ for `every`.
    pub(super) fn time_grad_of(&self, event: usize, j: usize, p: &X, dtau: &mut X) {
        let Some((_, grad, period)) = self.events.get(event).and_then(|e| e.time.as_ref()) else {
            dtau.fill(f64::NAN);
            return;
        };
        let row = self.tables.row(event, j);
        let at = TapeAt {
            row: &row,
            ..pt_theta(p)
        };
        self.vec_out(grad, &at, dtau);
        if let Some((_, per_grad)) = period {
            let mut sc = self.scratch.borrow_mut();
            let Scratch { regs, out, .. } = &mut *sc;
            self.eval(per_grad, &at, regs, out);
            for (d, g) in dtau.iter_mut().zip(out.iter()) {
                *d += j as f64 * g;
            }
        }
    }
}
