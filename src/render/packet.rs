//! Rays of one tile as structure-of-arrays, and the work queues between stages.
//!
//! All storage lives in the tile's `bumpalo` arena, reset per tile, so a frame
//! allocates nothing per ray. Stages address rays by index through queues
//! (`Queue`), so a ray's data never moves while it hops between stages.

use bumpalo::Bump;
use bumpalo::collections::Vec as BVec;
use glam::DVec3;

/// A queue of ray indices feeding one stage.
pub type Queue<'a> = BVec<'a, u32>;

/// How a ray ended, read by the record stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fate {
    /// Still travelling through the pipeline.
    Active,
    /// Left the volume (or never entered it): continues straight to the backdrop.
    Escaped,
    /// Stopped after `max_events` interface events: no backdrop hit.
    Terminated,
}

/// The rays of a tile, one entry per ray in every array.
/// (`Clone` only for tests that run two walks over the same rays.)
#[cfg_attr(test, derive(Clone))]
pub struct Rays<'a> {
    /// Image pixel index `y * width + x`.
    pub pixel: BVec<'a, u32>,
    /// The pixel's output slot in its region ([`TileOut`]: a rectangle's
    /// [`rect_slot`], a list's position), known when the ray is generated,
    /// so recording needs no division.
    ///
    /// [`rect_slot`]: super::tile::rect_slot
    ///
    /// [`TileOut`]: super::tile::TileOut
    pub slot: BVec<'a, u32>,
    /// Weight of this ray's colour in its pixel.
    pub weight: BVec<'a, f32>,
    /// True for the pixel-centre ray, which writes the hit-position image.
    pub centre: BVec<'a, bool>,
    /// World-space origin and unit direction of the current straight piece.
    pub org: [BVec<'a, f64>; 3],
    pub dir: [BVec<'a, f64>; 3],
    /// Current ray parameter (world units along `dir` from `org`).
    pub t: BVec<'a, f64>,
    /// Where the current straight piece starts (its entry into the domain,
    /// or just past the last crossing).
    pub t_start: BVec<'a, f64>,
    /// Where the current piece leaves the volume's bounds.
    pub t_end: BVec<'a, f64>,
    /// End of the segment handed to the solve stage.
    pub seg_end: BVec<'a, f64>,
    /// Field minus iso at `t` and `seg_end` (step traversal's bracket);
    /// empty for the cell traversals, which never read them.
    pub seg_g: [BVec<'a, f64>; 2],
    /// The reciprocal of the current piece's direction in knot-cell
    /// coordinates (0 where it is 0), set once per piece so the cell walk
    /// never divides. The piece's origin and direction in cell coordinates
    /// are not stored: recomputed from `org` and `dir` (two operations per
    /// axis, bitwise what was stored), the packet is a quarter smaller and
    /// stays in the L1 cache better.
    pub cell_inv: [BVec<'a, f64>; 3],
    /// Current knot cell (cell traversal).
    pub cell: [BVec<'a, i32>; 3],
    /// The traversal must first step past `cell` (its solve found nothing).
    pub advance: BVec<'a, bool>,
    /// Medium: inside the object (`f > iso`); valid once `side_known`.
    pub inside: BVec<'a, bool>,
    /// False from the entry stage until the first solve needs the medium: it
    /// is the field's side at the entry point (`t_start` of the first
    /// piece), and a ray that meets no candidate cell never needs it. Rays
    /// entering through a face of an active box with one side all over
    /// ([`crate::render::Ctx::entry_side`]) know it from the start.
    pub side_known: BVec<'a, bool>,
    pub events: BVec<'a, u32>,
    pub fate: BVec<'a, Fate>,
    /// Whether [`Rays::seg_g`] is kept.
    marches: bool,
}

impl<'a> Rays<'a> {
    /// Columns of `n` rays. Each gets a cache line more than it needs, so
    /// that consecutive columns do not start a multiple of 4 KiB apart: with
    /// 256 rays (a 16×16 tile), `f64` columns of exactly 2 KiB put ray `i` of
    /// every column in the same two sets of the L1 cache, and a stage
    /// touching a dozen columns per ray evicted its own lines.
    ///
    /// `marches` (step traversal) gives the rays the sampled field at their
    /// bracket's ends ([`Rays::seg_g`]).
    pub fn with_capacity_in(n: usize, marches: bool, bump: &'a Bump) -> Rays<'a> {
        let n = n + 64 / std::mem::size_of::<f64>();
        let f = || BVec::with_capacity_in(n, bump);
        let g = || BVec::with_capacity_in(if marches { n } else { 0 }, bump);
        Rays {
            pixel: BVec::with_capacity_in(n, bump),
            slot: BVec::with_capacity_in(n, bump),
            weight: BVec::with_capacity_in(n, bump),
            centre: BVec::with_capacity_in(n, bump),
            org: [f(), f(), f()],
            dir: [f(), f(), f()],
            t: f(),
            t_start: f(),
            t_end: f(),
            seg_end: f(),
            seg_g: [g(), g()],
            marches,
            cell_inv: [f(), f(), f()],
            cell: [
                BVec::with_capacity_in(n, bump),
                BVec::with_capacity_in(n, bump),
                BVec::with_capacity_in(n, bump),
            ],
            advance: BVec::with_capacity_in(n, bump),
            inside: BVec::with_capacity_in(n, bump),
            side_known: BVec::with_capacity_in(n, bump),
            events: BVec::with_capacity_in(n, bump),
            fate: BVec::with_capacity_in(n, bump),
        }
    }

    pub fn len(&self) -> usize {
        self.pixel.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }

    /// Appends a fresh ray's identity (its image pixel and that pixel's
    /// output slot), origin and direction; returns its index. The other
    /// columns lag behind until [`Rays::complete`]: the generator fills them
    /// for all its rays at once (a bulk fill per column where a push per ray
    /// and column cost a fifth of the stage).
    #[inline]
    pub fn push(
        &mut self,
        (pixel, slot): (u32, u32),
        weight: f32,
        centre: bool,
        org: DVec3,
        dir: DVec3,
    ) -> u32 {
        let i = self.len() as u32;
        self.pixel.push(pixel);
        self.slot.push(slot);
        self.weight.push(weight);
        self.centre.push(centre);
        for a in 0..3 {
            self.org[a].push(org[a]);
            self.dir[a].push(dir[a]);
        }
        i
    }

    /// Appends the pixel-centre rays of `len ≤ 8` pixels sharing the origin
    /// `org` (a perspective camera's): their identities (image pixels from
    /// `pixel`, output slots from `slot`, consecutive), unit weight, and
    /// directions `dir[axis][lane]`. A slice per column where a push per ray
    /// and column cost most of the generate stage. Inlined into the entry
    /// stage, whose instruction set it then runs in.
    #[inline(always)]
    pub fn push_centre_run(
        &mut self,
        (pixel, slot): (u32, u32),
        len: usize,
        org: DVec3,
        dir: &[[f64; 8]; 3],
    ) {
        let ids: [u32; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
        self.pixel.extend_from_slice(&ids.map(|l| pixel + l)[..len]);
        self.slot.extend_from_slice(&ids.map(|l| slot + l)[..len]);
        self.weight.extend_from_slice(&[1.0; 8][..len]);
        self.centre.extend_from_slice(&[true; 8][..len]);
        for a in 0..3 {
            self.org[a].extend_from_slice(&[org[a]; 8][..len]);
            self.dir[a].extend_from_slice(&dir[a][..len]);
        }
    }

    /// Brings every other column up to the pushed rays, with the values a
    /// fresh ray starts from.
    pub fn complete(&mut self) {
        let n = self.len();
        for a in 0..3 {
            self.cell[a].resize(n, 0);
            self.cell_inv[a].resize(n, 0.0);
        }
        for col in [
            &mut self.t,
            &mut self.t_start,
            &mut self.t_end,
            &mut self.seg_end,
        ] {
            col.resize(n, 0.0);
        }
        if self.marches {
            for col in &mut self.seg_g {
                col.resize(n, 0.0);
            }
        }
        self.advance.resize(n, false);
        self.inside.resize(n, false);
        self.side_known.resize(n, true);
        self.events.resize(n, 0);
        self.fate.resize(n, Fate::Active);
    }

    #[inline(always)]
    pub fn origin(&self, i: usize) -> DVec3 {
        DVec3::new(self.org[0][i], self.org[1][i], self.org[2][i])
    }

    #[inline(always)]
    pub fn direction(&self, i: usize) -> DVec3 {
        DVec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i])
    }

    #[inline(always)]
    pub fn set_origin(&mut self, i: usize, o: DVec3) {
        for a in 0..3 {
            self.org[a][i] = o[a];
        }
    }

    #[inline(always)]
    pub fn set_direction(&mut self, i: usize, d: DVec3) {
        for a in 0..3 {
            self.dir[a][i] = d[a];
        }
    }

    #[inline(always)]
    pub fn cell_of(&self, i: usize) -> [i64; 3] {
        [
            self.cell[0][i] as i64,
            self.cell[1][i] as i64,
            self.cell[2][i] as i64,
        ]
    }

    #[inline(always)]
    pub fn set_cell(&mut self, i: usize, c: [i64; 3]) {
        for a in 0..3 {
            self.cell[a][i] = c[a] as i32;
        }
    }
}
