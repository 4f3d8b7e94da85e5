//! The effect of a switching operation, shown before it is executed:
//! sections and customers that lose or gain supply, sections earthed or
//! no longer earthed, sources newly paralleled, loops made or broken.

use crate::model::{Model, SecIdx};
use crate::topology::{Parallel, SectionState, Topology};

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Preview {
    /// Energised before, dead, earthed or unknown after.
    pub lose_supply: Vec<SecIdx>,
    /// Not energised before, energised after.
    pub gain_supply: Vec<SecIdx>,
    pub customers_lose: u64,
    pub customers_gain: u64,
    pub newly_earthed: Vec<SecIdx>,
    pub no_longer_earthed: Vec<SecIdx>,
    /// Energised and earthed after, and not before.
    pub energised_earthed: Vec<SecIdx>,
    /// Known before, unknown after.
    pub becomes_unknown: Vec<SecIdx>,
    /// Certain parallels after that were not there before.
    pub new_parallels: Vec<Parallel>,
    /// Certain parallels before that are gone after.
    pub ended_parallels: Vec<Parallel>,
    pub loops_before: usize,
    pub loops_after: usize,
}

fn certain(t: &Topology) -> impl Iterator<Item = &Parallel> {
    t.parallels.iter().filter(|p| p.certain)
}

/// What changes from `before` to `after` (two results of
/// [`crate::compute`] over the same model).
pub fn preview(model: &Model, before: &Topology, after: &Topology) -> Preview {
    let mut p = Preview {
        loops_before: before.loops(),
        loops_after: after.loops(),
        ..Preview::default()
    };
    for (s, (&was, &now)) in before.state.iter().zip(&after.state).enumerate() {
        let s = s as SecIdx;
        if was.energised() && !now.energised() {
            p.lose_supply.push(s);
        } else if !was.energised() && now.energised() {
            p.gain_supply.push(s);
        }
        if !was.earthed() && now.earthed() {
            p.newly_earthed.push(s);
        } else if was.earthed() && !now.earthed() {
            p.no_longer_earthed.push(s);
        }
        if now == SectionState::EnergisedEarthed && was != SectionState::EnergisedEarthed {
            p.energised_earthed.push(s);
        }
        if now == SectionState::Unknown && was != SectionState::Unknown {
            p.becomes_unknown.push(s);
        }
    }
    p.customers_lose = model.customers(&p.lose_supply);
    p.customers_gain = model.customers(&p.gain_supply);
    p.new_parallels = certain(after)
        .filter(|a| !certain(before).any(|b| b.sources == a.sources))
        .cloned()
        .collect();
    p.ended_parallels = certain(before)
        .filter(|b| !certain(after).any(|a| a.sources == b.sources))
        .cloned()
        .collect();
    p
}
