//! Roofs that change between visits: the world of a later visit is the world of the visit before
//! with, on each roof independently, rooftop assets added, removed or moved and tarps laid down.
//!
//! [`revise`] draws the changes of one visit from a stream of its own per roof (seeded by the
//! world's seed, the visit and the building), so the changes of a roof depend only on that roof's
//! history, and the same seed gives the same changes. On each roof and visit each of the four
//! changes happens with its own probability ([`ChangeRates`]):
//!
//! | change | rate | what |
//! |---|---|---|
//! | added | 0.20 | a new AC unit, seating or planter ([`ADDED_KINDS`]) at a free place |
//! | removed | 0.20 | one loose asset ([`AssetKind`]s that are not part of the building: vents, AC units, seating, ducts, tarps, planters) taken away |
//! | moved | 0.50 | one movable asset (AC unit, seating, tarp, planter) taken to a free place clear of where it was; higher because only about one roof in four has one at first |
//! | tarp | 0.15 | a tarp laid down at a free place |
//!
//! The rates are far higher than a real city's in an hour: they are chosen so that an
//! evaluation over a few visits sees every kind of change on its target roofs, while about half
//! the roofs stay as they were at each visit, so that what a catalog keeps is tested as much as
//! what it replaces. The default set (`scenarios --seed 2026 --revisits 2`: 6 worlds of 115
//! roofs, 36 target roofs) gets 841 changes, and on its 72 target roof-visits 10 additions,
//! 7 removals, 19 moves and 6 tarps; 49 % of the roof-visits change, and 65 of the 72 revisit
//! approaches have a changed roof in view. A change that finds no room, or no asset to act on,
//! does not happen and is not reported.
//! Changes add to each other over visits: visit 2's world is visit 1's, changed again.
//!
//! ```
//! use landing_sim::revisit::{ChangeRates, revise};
//! use landing_sim::{World, WorldConfig};
//!
//! let world = World::generate(3, &WorldConfig::default()).unwrap();
//! let (later, changes) = revise(&world, 1, &ChangeRates::default()).unwrap();
//! assert!(!changes.is_empty());
//! assert_eq!(later.buildings.len(), world.buildings.len());
//! ```

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use crate::SimError;
use crate::assets::AssetKind;
use crate::world::{Asset, AssetSource, Building, World, asset_size, place_sized};

/// Per roof and visit, the probability of each change (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChangeRates {
    pub add: f64,
    pub remove: f64,
    pub moved: f64,
    pub tarp: f64,
}

impl Default for ChangeRates {
    fn default() -> Self {
        Self {
            add: 0.2,
            remove: 0.2,
            moved: 0.5,
            tarp: 0.15,
        }
    }
}

impl ChangeRates {
    /// No roof ever changes.
    pub const NONE: ChangeRates = ChangeRates {
        add: 0.0,
        remove: 0.0,
        moved: 0.0,
        tarp: 0.0,
    };

    /// Checks that every rate is a probability.
    pub fn validate(&self) -> Result<(), SimError> {
        for (field, v) in [
            ("change_rates.add", self.add),
            ("change_rates.remove", self.remove),
            ("change_rates.moved", self.moved),
            ("change_rates.tarp", self.tarp),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(SimError::invalid(
                    field,
                    v,
                    "must be a probability in 0..=1",
                ));
            }
        }
        Ok(())
    }
}

/// The kinds an added asset is drawn from, equally likely: things that appear on a roof between
/// two flights (a tarp is its own change).
pub const ADDED_KINDS: [AssetKind; 3] =
    [AssetKind::AcUnit, AssetKind::Seating, AssetKind::Vegetation];

/// Whether an asset of `kind` can be taken away: it is not part of the building.
pub fn is_loose(kind: AssetKind) -> bool {
    matches!(
        kind,
        AssetKind::AirVents
            | AssetKind::AcUnit
            | AssetKind::Seating
            | AssetKind::AirDucts
            | AssetKind::Tarp
            | AssetKind::Vegetation
    )
}

/// Whether an asset of `kind` gets moved about a roof.
pub fn is_movable(kind: AssetKind) -> bool {
    matches!(
        kind,
        AssetKind::AcUnit | AssetKind::Seating | AssetKind::Tarp | AssetKind::Vegetation
    )
}

/// What happened to a roof.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ChangeKind {
    Added,
    Removed,
    Moved,
    /// A tarp laid down.
    Tarp,
}

impl ChangeKind {
    pub const ALL: [ChangeKind; 4] = [Self::Added, Self::Removed, Self::Moved, Self::Tarp];

    /// Its name in manifests: "added", "removed", "moved", "tarp".
    pub fn name(self) -> &'static str {
        match self {
            Self::Added => "added",
            Self::Removed => "removed",
            Self::Moved => "moved",
            Self::Tarp => "tarp",
        }
    }
}

/// One change of one roof between a visit and the one before.
#[derive(Debug, Clone, PartialEq)]
pub struct RoofChange {
    pub building: usize,
    pub change: ChangeKind,
    pub asset: AssetKind,
    /// The asset's height above the roof, metres.
    pub height_m: f64,
    /// Its footprint before the change (removed, moved), counter-clockwise.
    pub before: Option<Vec<[f64; 2]>>,
    /// Its footprint after the change (added, moved, tarp), counter-clockwise.
    pub after: Option<Vec<[f64; 2]>>,
    /// Its index in the changed world's [`World::assets`] (added, moved, tarp).
    pub asset_index: Option<usize>,
}

/// The world of visit `visit` (1, 2, …) from the world of the visit before, and what changed,
/// roof by roof in building order (see the module docs).
pub fn revise(
    world: &World,
    visit: u32,
    rates: &ChangeRates,
) -> Result<(World, Vec<RoofChange>), SimError> {
    rates.validate()?;
    let mut assets: Vec<(Asset, AssetSource)> = Vec::with_capacity(world.assets.len() + 8);
    let mut changes = Vec::new();
    for bi in 0..world.buildings.len() {
        let mut roof = Roof::of(world, bi, visit);
        let first = assets.len();
        let mut of_roof = roof.change(rates);
        for c in &mut of_roof {
            // The roof's assets keep their order, after those of the buildings before it.
            c.asset_index = c.asset_index.map(|i| first + i);
        }
        assets.extend(roof.assets);
        changes.extend(of_roof);
    }
    Ok((world.with_assets(&assets)?, changes))
}

/// One roof being changed: its assets (where each comes from) and its own random stream.
struct Roof<'a> {
    building: &'a Building,
    bi: usize,
    assets: Vec<(Asset, AssetSource)>,
    rng: SmallRng,
}

impl<'a> Roof<'a> {
    fn of(world: &'a World, bi: usize, visit: u32) -> Self {
        let building = &world.buildings[bi];
        let assets = building
            .assets
            .iter()
            .map(|&i| (world.assets[i].clone(), AssetSource::Kept(i)))
            .collect();
        let seed = (world.seed ^ 0x7265_7669_7369_7473)
            .wrapping_add(u64::from(visit).wrapping_mul(0xd1b5_4a32_d192_ed03))
            .wrapping_add((bi as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        Roof {
            building,
            bi,
            assets,
            rng: SmallRng::seed_from_u64(seed),
        }
    }

    /// Draws whether each change happens, then makes those that do, in a fixed order: remove
    /// (first, so that the indices the others record stay), move, add, tarp. Asset indices in
    /// the result are the roof's own.
    fn change(&mut self, rates: &ChangeRates) -> Vec<RoofChange> {
        let draws =
            [rates.remove, rates.moved, rates.add, rates.tarp].map(|p| self.rng.random_bool(p));
        let mut out = Vec::new();
        if draws[0] {
            out.extend(self.remove());
        }
        if draws[1] {
            out.extend(self.move_one());
        }
        if draws[2] {
            let kind = ADDED_KINDS[self.rng.random_range(0..ADDED_KINDS.len())];
            out.extend(self.add(kind, ChangeKind::Added));
        }
        if draws[3] {
            out.extend(self.add(AssetKind::Tarp, ChangeKind::Tarp));
        }
        out
    }

    /// One of the roof's assets that `keep` accepts, drawn at random.
    fn pick(&mut self, keep: fn(AssetKind) -> bool) -> Option<usize> {
        let candidates: Vec<usize> = (0..self.assets.len())
            .filter(|&i| keep(self.assets[i].0.kind))
            .collect();
        (!candidates.is_empty()).then(|| candidates[self.rng.random_range(0..candidates.len())])
    }

    fn remove(&mut self) -> Option<RoofChange> {
        let i = self.pick(is_loose)?;
        let (a, _) = self.assets.remove(i);
        Some(RoofChange {
            building: self.bi,
            change: ChangeKind::Removed,
            asset: a.kind,
            height_m: a.height_m,
            before: Some(a.footprint()),
            after: None,
            asset_index: None,
        })
    }

    fn move_one(&mut self) -> Option<RoofChange> {
        let i = self.pick(is_movable)?;
        let a = self.assets[i].0.clone();
        // Clear of every asset, its own old place included, so that it really moves.
        let others: Vec<&Asset> = self.assets.iter().map(|(o, _)| o).collect();
        let size = (a.half_extents, a.height_m);
        let moved = place_sized(a.kind, size, self.building, self.bi, &others, &mut self.rng)?;
        let change = RoofChange {
            building: self.bi,
            change: ChangeKind::Moved,
            asset: a.kind,
            height_m: a.height_m,
            before: Some(a.footprint()),
            after: Some(moved.footprint()),
            asset_index: Some(i),
        };
        self.assets[i].0 = moved;
        Some(change)
    }

    fn add(&mut self, kind: AssetKind, change: ChangeKind) -> Option<RoofChange> {
        let size = asset_size(kind, &mut self.rng);
        let others: Vec<&Asset> = self.assets.iter().map(|(o, _)| o).collect();
        let a = place_sized(kind, size, self.building, self.bi, &others, &mut self.rng)?;
        let looks = self.rng.random();
        let out = RoofChange {
            building: self.bi,
            change,
            asset: kind,
            height_m: a.height_m,
            before: None,
            after: Some(a.footprint()),
            asset_index: Some(self.assets.len()),
        };
        self.assets.push((a, AssetSource::New(looks)));
        Some(out)
    }
}
