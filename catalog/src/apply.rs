//! The update rule's driver, shared by both stores: per observation, fetch what it can reach,
//! [`plan`] and write.

use crate::error::Result;
use crate::geo::{Bbox, Polygon};
use crate::model::{Observation, Site, SiteId};
use crate::rule::{ApplyReport, plan};
use crate::time::Timestamp;

/// Metres added around every box a store is asked about: covers rounding of coordinates and the
/// R*Tree's 32-bit boxes (which round outward: a few metres at most at Earth's scale).
pub(crate) const BOX_PAD_M: f64 = 2.0;

/// A store's writes inside one open transaction.
pub(crate) trait WriteTx {
    /// Every confirmed site whose box meets `bbox` (more is fine).
    fn confirmed_in(&mut self, bbox: &Bbox) -> Result<Vec<Site>>;
    /// Every seen area recorded after `t` whose box meets `bbox` (more is fine).
    fn seen_after(&mut self, bbox: &Bbox, t: Timestamp) -> Result<Vec<(Timestamp, Polygon)>>;
    fn insert(&mut self, site: &Site) -> Result<SiteId>;
    fn update(&mut self, site: &Site) -> Result<()>;
    fn delete(&mut self, id: SiteId) -> Result<()>;
    /// Records what one observation saw (a few hundred rectangles: one statement where it can).
    fn record_seen(&mut self, t: Timestamp, areas: &[Polygon]) -> Result<()>;
}

/// Validates the whole batch, then applies it oldest first.
pub(crate) fn validate(batch: &[Observation]) -> Result<Vec<&Observation>> {
    for (i, o) in batch.iter().enumerate() {
        o.validate(&format!("observations[{i}]"))?;
    }
    let mut sorted: Vec<&Observation> = batch.iter().collect();
    sorted.sort_by_key(|o| o.t);
    Ok(sorted)
}

/// Applies validated, sorted observations through `tx`.
pub(crate) fn apply_sorted(tx: &mut impl WriteTx, sorted: &[&Observation]) -> Result<ApplyReport> {
    let mut report = ApplyReport::default();
    for obs in sorted {
        let reach = obs.reach().padded_m(BOX_PAD_M);
        let (stored, newer) = if reach.is_empty() {
            (Vec::new(), Vec::new())
        } else {
            (tx.confirmed_in(&reach)?, tx.seen_after(&reach, obs.t)?)
        };
        let p = plan(obs, &stored, &newer);
        for id in &p.deletes {
            tx.delete(*id)?;
        }
        for s in &p.updates {
            tx.update(s)?;
        }
        for s in &p.inserts {
            tx.insert(s)?;
        }
        if !obs.seen.is_empty() {
            tx.record_seen(obs.t, &obs.seen)?;
        }
        report += p.report;
    }
    Ok(report)
}
