//! The map's top surface kept between scans, with its Delaunay triangulation
//! ([`crate::FusionMap::meshed_surface`]).
//!
//! Between two scans of an approach most of the map stays as it was: a scan moves the means of
//! the cells it hits and adds cells at the edge of what was seen. The top surface's points
//! (one per x/y column) are therefore kept, each column in the place it first took, and only the
//! columns a scan changed are read again; their triangulation is a
//! [`KeptTriangulation`], repaired where those points moved or appeared instead of made again
//! from every point. When cells are forgotten (the horizon, the cell bound) or the map starts
//! over, the columns are read again from all the cells, in key order, and triangulated from
//! scratch. The class each column's top cell decides is kept the same way: decided again only
//! for the columns whose top cell a scan voted on, resolved or replaced
//! ([`crate::FusionMap::meshed_classes`]).

use std::collections::HashMap;
use std::hash::BuildHasherDefault;

use landing_geometry::delaunay::KeptTriangulation;
use landing_geometry::{GeometryError, Triangulation};

use crate::{CLASSES, CellHasher, Surface};

/// The map's top surface in the map's own coordinates, with its Delaunay triangulation.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshedSurface {
    /// The surface's columns (their top cells and mean points, world frame), in the map's kept
    /// order: the order [`crate::FusionMap::surface`] gives them when the columns were last read
    /// from all the cells, then each new column after them as it appeared.
    pub surface: Surface,
    /// The same points relative to the map's origin, in the single precision the geometry
    /// takes (`landing_geometry::Cloud`'s points).
    pub points: Vec<[f32; 3]>,
    /// A Delaunay triangulation of `points`' x/y, the one
    /// `landing_geometry::triangulate_points` makes but for the order of its triangles (and
    /// which diagonal of four points on one circle it keeps).
    pub triangulation: Result<Triangulation, GeometryError>,
}

/// The columns of the map's top surface, kept between scans (see the module docs).
#[derive(Debug, Default)]
pub(crate) struct Columns {
    /// Each column's place, by its x/y cell.
    place: HashMap<[i32; 2], u32, BuildHasherDefault<CellHasher>>,
    /// Per place, the key of the column's top cell.
    top: Vec<[i32; 3]>,
    /// Per place, the top cell's mean point, world frame.
    world: Vec<[f64; 3]>,
    /// Per place, the same relative to the map's origin, single precision.
    local: Vec<[f32; 3]>,
    /// Places whose top point moved or that are new since the surface was last meshed.
    changed: Vec<u32>,
    /// Cells were forgotten: the columns are to be read again from all the cells.
    stale: bool,
    mesh: KeptTriangulation,
    /// Per place, the class its top cell decides and whether it is landable ground not yet
    /// seen finely, for the landable classes `decided_for`.
    class: Vec<u8>,
    unresolved: Vec<bool>,
    /// Places whose top cell took points (and so votes), was resolved or is another cell since
    /// the classes were last decided.
    redecide: Vec<u32>,
    /// The landable classes `class` was decided for; `None`: to be decided for every place.
    decided_for: Option<[bool; CLASSES]>,
}

impl Columns {
    /// Columns to be read from the cells when next meshed.
    pub(crate) fn new() -> Self {
        Self {
            stale: true,
            ..Self::default()
        }
    }

    /// The cell `key` took points: its column's top point moved if it is the top, or the cell is
    /// the column's new top, or the first cell of a new column.
    pub(crate) fn touch(&mut self, key: [i32; 3]) {
        if self.stale {
            return;
        }
        match self.place.get(&[key[0], key[1]]) {
            Some(&at) => {
                let top = &mut self.top[at as usize];
                if key[2] >= top[2] {
                    *top = key;
                    self.changed.push(at);
                    if self.decided_for.is_some() {
                        self.redecide.push(at);
                    }
                }
            }
            None => {
                let at = self.top.len() as u32;
                self.place.insert([key[0], key[1]], at);
                self.top.push(key);
                self.world.push([0.0; 3]);
                self.local.push([0.0; 3]);
                self.changed.push(at);
                if self.decided_for.is_some() {
                    self.redecide.push(at);
                }
            }
        }
    }

    /// The cell `key` was resolved: its column's class is decided again if it is the column's
    /// top. (Votes need no call: a scan votes only in the cells it placed points in, which
    /// [`Columns::touch`] named.)
    pub(crate) fn resolved(&mut self, key: [i32; 3]) {
        if self.stale || self.decided_for.is_none() {
            return;
        }
        if let Some(&at) = self.place.get(&[key[0], key[1]])
            && self.top[at as usize] == key
        {
            self.redecide.push(at);
        }
    }

    /// The class and unresolved flag of every column's top cell, for the `landable` classes:
    /// `decide` gives them for a list of cells. Only the columns [`Columns::touch`] and
    /// [`Columns::resolved`] named since the last call are decided again, unless the landable
    /// classes differ or there is nothing kept yet.
    pub(crate) fn classes(
        &mut self,
        landable: [bool; CLASSES],
        decide: impl Fn(&[[i32; 3]]) -> (Vec<u8>, Vec<bool>),
    ) -> (&[u8], &[bool]) {
        if self.decided_for == Some(landable) {
            self.redecide.sort_unstable();
            self.redecide.dedup();
            self.class.resize(self.top.len(), 0);
            self.unresolved.resize(self.top.len(), false);
            let keys: Vec<[i32; 3]> = (self.redecide.iter())
                .map(|&at| self.top[at as usize])
                .collect();
            let (class, unresolved) = decide(&keys);
            for ((&at, c), u) in self.redecide.iter().zip(class).zip(unresolved) {
                self.class[at as usize] = c;
                self.unresolved[at as usize] = u;
            }
        } else {
            (self.class, self.unresolved) = decide(&self.top);
            self.decided_for = Some(landable);
        }
        self.redecide.clear();
        (&self.class, &self.unresolved)
    }

    /// Cells were forgotten (or all of them): read the columns again when next meshed.
    pub(crate) fn forget(&mut self) {
        self.stale = true;
        self.place.clear();
        self.top.clear();
        self.world.clear();
        self.local.clear();
        self.changed.clear();
        self.forget_classes();
    }

    /// The kept classes are to be decided again for every place.
    fn forget_classes(&mut self) {
        self.class.clear();
        self.unresolved.clear();
        self.redecide.clear();
        self.decided_for = None;
    }

    /// The surface and its triangulation now: `all` gives the whole surface in key order (when
    /// the columns are stale), `position` a cell's mean point, world frame; `origin` is the
    /// map's.
    pub(crate) fn meshed(
        &mut self,
        all: impl FnOnce() -> Surface,
        position: impl Fn(&[i32; 3]) -> [f64; 3],
        origin: [f64; 3],
    ) -> MeshedSurface {
        let local =
            |p: &[f64; 3]| -> [f32; 3] { std::array::from_fn(|i| (p[i] - origin[i]) as f32) };
        let triangulated = if self.stale {
            let surface = all();
            self.place = surface
                .keys
                .iter()
                .enumerate()
                .map(|(at, key)| ([key[0], key[1]], at as u32))
                .collect();
            self.local = surface.points.iter().map(local).collect();
            self.top = surface.keys;
            self.world = surface.points;
            self.changed.clear();
            self.forget_classes();
            self.stale = false;
            self.mesh.rebuild(&self.local)
        } else {
            self.changed.sort_unstable();
            self.changed.dedup();
            for &at in &self.changed {
                let at = at as usize;
                self.world[at] = position(&self.top[at]);
                self.local[at] = local(&self.world[at]);
            }
            let kept = self.mesh.update(&self.local, &self.changed);
            self.changed.clear();
            kept
        };
        MeshedSurface {
            surface: Surface {
                keys: self.top.clone(),
                points: self.world.clone(),
            },
            points: self.local.clone(),
            triangulation: triangulated.map(|()| self.mesh.triangulation()),
        }
    }

    /// Each column's top cell, in the kept order.
    #[cfg(debug_assertions)]
    pub(crate) fn top_keys(&self) -> &[[i32; 3]] {
        &self.top
    }

    /// What the kept triangulation has done so far.
    pub(crate) fn mesh_stats(&self) -> landing_geometry::delaunay::KeptStats {
        self.mesh.stats()
    }

    /// Bytes the columns and their triangulation take.
    pub(crate) fn bytes(&self) -> usize {
        self.place.capacity() * (std::mem::size_of::<([i32; 2], u32)>() + 1)
            + self.top.capacity() * std::mem::size_of::<[i32; 3]>()
            + self.world.capacity() * std::mem::size_of::<[f64; 3]>()
            + self.local.capacity() * std::mem::size_of::<[f32; 3]>()
            + self.changed.capacity() * 4
            + self.mesh.bytes()
            + self.class.capacity()
            + self.unresolved.capacity()
            + self.redecide.capacity() * 4
    }
}
