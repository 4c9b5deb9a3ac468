//! What the event loop watches in each mode (decided once per run).

use crate::model::{HybridModel, ModelAlloc};
use nalgebra::DefaultAllocator;

/// What the scanner watches in one mode: every switching function and the state events armed
/// there (time events are not watched: the loop steps onto their times), and whether all of
/// them are affine guards (a mode with a switching function is not).
pub(super) struct ModeWatch {
    /// The functions active in the mode, ascending.
    pub(super) list: Vec<usize>,
    /// Some function is active.
    pub(super) any: bool,
    /// Every active function is an affine guard.
    pub(super) affine: bool,
    /// The active functions that are not affine guards: steps are cut until they are
    /// resolved (see `resolution`).
    pub(super) unresolved: Vec<usize>,
}

impl ModeWatch {
    /// The watch of every mode of `model`.
    pub(super) fn of_modes<M: HybridModel>(model: &M) -> Vec<ModeWatch>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        let info = model.info();
        let nev = info.events.len();
        (0..info.modes.len())
            .map(|mode| {
                let active: Vec<bool> = (0..nev + info.switches)
                    .map(|w| {
                        w >= nev
                            || (info.events[w].armed_in(mode) && !info.events[w].is_time_event())
                    })
                    .collect();
                let affine = active
                    .iter()
                    .enumerate()
                    .all(|(w, &a)| !a || (w < nev && model.guard_is_affine(w)));
                let list: Vec<usize> = (0..active.len()).filter(|&w| active[w]).collect();
                let unresolved = list
                    .iter()
                    .copied()
                    .filter(|&w| w >= nev || !model.guard_is_affine(w))
                    .collect();
                ModeWatch {
                    any: !list.is_empty(),
                    list,
                    affine,
                    unresolved,
                }
            })
            .collect()
    }
}
