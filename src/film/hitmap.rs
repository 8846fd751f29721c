//! The hit-position image as a map from the image plane to the backdrop,
//! `M: (x, y) → (u, v)`, sampled at pixel centres: neighbour lookups that
//! respect discontinuities, and local derivatives.
//!
//! Two pixels lie on the same smooth piece of `M` only if both reach the
//! backdrop and crossed the same number of interfaces; across a silhouette or
//! a change of interface chain `M` jumps, and differences taken across it mean
//! nothing.

use super::Film;
use rayon::prelude::*;

/// What a neighbour is, seen from a pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Neighbour {
    /// On the same piece of the map as the centre (for a centre without a
    /// hit: also without one). Pixels outside the image count as this too:
    /// the image border is not an edge of the scene.
    Same,
    /// Reaches no backdrop while the centre does.
    NoHit,
    /// On another piece: its hit and event count.
    Other([f64; 2], f32),
}

/// The hit map with neighbour lookups.
pub(crate) struct HitMap<'a> {
    film: &'a Film,
    pub w: i64,
    pub h: i64,
    /// Per pixel, its piece as one number: the event count where it reaches
    /// the backdrop, [`NO_HIT`] where not ([`HitMap::keys`]).
    keys: Vec<f32>,
}

/// [`HitMap::keys`] of a pixel without a backdrop hit: below every event
/// count (counts are finite and non-negative).
pub(crate) const NO_HIT: f32 = f32::NEG_INFINITY;

/// `dM/dx` and `dM/dy` (backdrop units per pixel; `y` grows downwards), where
/// they can be estimated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Jacobian {
    pub dx: Option<[f64; 2]>,
    pub dy: Option<[f64; 2]>,
}

impl Jacobian {
    /// Missing derivatives as zero (the map held constant that way).
    pub fn or_zero(&self) -> [[f64; 2]; 2] {
        [self.dx.unwrap_or([0.0; 2]), self.dy.unwrap_or([0.0; 2])]
    }

    /// The linear map at offset `(a, b)` pixels from `hit`.
    pub fn apply(&self, hit: [f64; 2], a: f64, b: f64) -> [f64; 2] {
        let [jx, jy] = self.or_zero();
        [
            hit[0] + a * jx[0] + b * jy[0],
            hit[1] + a * jx[1] + b * jy[1],
        ]
    }
}

impl<'a> HitMap<'a> {
    pub fn new(film: &'a Film) -> HitMap<'a> {
        // In parallel: a serial pass over the image was 0.6 ms of the
        // sphere's PRSS stage on 2 threads.
        let keys = (film.u.par_iter().zip(&film.v).zip(&film.events))
            .map(|((u, v), &e)| {
                if u.is_finite() && v.is_finite() {
                    e
                } else {
                    NO_HIT
                }
            })
            .collect();
        HitMap {
            film,
            w: film.width as i64,
            h: film.height as i64,
            keys,
        }
    }

    /// Per pixel (row-major), one number for its piece: pixel `i` is on the
    /// piece of a centre with hit state `centre` exactly when
    /// `keys()[i] == centre.unwrap_or(NO_HIT)` (what
    /// [`HitMap::same_piece`] answers).
    pub fn keys(&self) -> &[f32] {
        &self.keys
    }

    /// The film the map reads.
    #[inline]
    pub fn film(&self) -> &'a Film {
        self.film
    }

    #[inline]
    pub fn inside(&self, x: i64, y: i64) -> bool {
        x >= 0 && y >= 0 && x < self.w && y < self.h
    }

    /// The pixel's hit and event count, if it reaches the backdrop.
    #[inline]
    pub fn at(&self, x: i64, y: i64) -> Option<([f64; 2], f32)> {
        if !self.inside(x, y) {
            return None;
        }
        let i = (y * self.w + x) as usize;
        let (u, v) = (self.film.u[i], self.film.v[i]);
        if u.is_finite() && v.is_finite() {
            Some(([u as f64, v as f64], self.film.events[i]))
        } else {
            None
        }
    }

    /// The neighbour's hit if it is on the piece with event count `ev`.
    #[inline]
    pub fn consistent(&self, x: i64, y: i64, ev: f32) -> Option<[f64; 2]> {
        self.at(x, y).filter(|(_, e)| *e == ev).map(|(h, _)| h)
    }

    /// Whether pixel `(x, y)` (inside the image) is on the piece of a centre
    /// with hit state `centre`: `neighbour(x, y, centre) == Neighbour::Same`
    /// without building the neighbour.
    #[inline(always)]
    pub fn same_piece(&self, x: i64, y: i64, centre: Option<f32>) -> bool {
        self.keys[(y * self.w + x) as usize] == centre.unwrap_or(NO_HIT)
    }

    /// How pixel `(x, y)` relates to a centre with hit state `centre`.
    #[inline]
    pub fn neighbour(&self, x: i64, y: i64, centre: Option<f32>) -> Neighbour {
        if !self.inside(x, y) {
            return Neighbour::Same;
        }
        match (self.at(x, y), centre) {
            (None, None) => Neighbour::Same,
            (None, Some(_)) => Neighbour::NoHit,
            (Some((_, e)), Some(ev)) if e == ev => Neighbour::Same,
            (Some((h, e)), _) => Neighbour::Other(h, e),
        }
    }

    /// Derivatives at `(x, y)` (hit `centre`, events `ev`) from neighbours on
    /// the same piece: central differences where both sides are, one-sided
    /// where one is.
    pub fn jacobian(&self, x: i64, y: i64, centre: [f64; 2], ev: f32) -> Jacobian {
        if x >= 1 && y >= 1 && x + 1 < self.w && y + 1 < self.h {
            return self.jacobian_inside(x, y, centre, ev);
        }
        self.jacobian_checked(x, y, centre, ev)
    }

    /// [`HitMap::jacobian`] anywhere: each neighbour looked up with its
    /// bounds and piece checked.
    fn jacobian_checked(&self, x: i64, y: i64, centre: [f64; 2], ev: f32) -> Jacobian {
        let deriv = |dx: i64, dy: i64| -> Option<[f64; 2]> {
            let f = self.consistent(x + dx, y + dy, ev);
            let b = self.consistent(x - dx, y - dy, ev);
            match (f, b) {
                (Some(f), Some(b)) => Some([0.5 * (f[0] - b[0]), 0.5 * (f[1] - b[1])]),
                (Some(f), None) => Some([f[0] - centre[0], f[1] - centre[1]]),
                (None, Some(b)) => Some([centre[0] - b[0], centre[1] - b[1]]),
                (None, None) => None,
            }
        };
        Jacobian {
            dx: deriv(1, 0),
            dy: deriv(0, 1),
        }
    }

    /// [`HitMap::jacobian`] at a pixel whose four neighbours are inside the
    /// image, the same bits with selects for the four cases instead of
    /// branches on them, which PRSS takes at boundaries, where they go
    /// either way (with the grid's selects, teapot: the blended pixels'
    /// ring and grid 18–19 → 11–14 M cycles a frame).
    #[inline]
    fn jacobian_inside(&self, x: i64, y: i64, centre: [f64; 2], ev: f32) -> Jacobian {
        let at = (y * self.w + x) as usize;
        let deriv = |step: usize| {
            let (f, b) = (at + step, at - step);
            let (on_f, on_b) = (self.keys[f] == ev, self.keys[b] == ev);
            let hit = |i: usize| [self.film.u[i] as f64, self.film.v[i] as f64];
            // Both: the central difference; one: the one-sided difference
            // against the centre (times 1, exactly).
            let ahead = if on_f { hit(f) } else { centre };
            let behind = if on_b { hit(b) } else { centre };
            let half = if on_f && on_b { 0.5 } else { 1.0 };
            let d = [half * (ahead[0] - behind[0]), half * (ahead[1] - behind[1])];
            (on_f || on_b).then_some(d)
        };
        Jacobian {
            dx: deriv(1),
            dy: deriv(self.w as usize),
        }
    }

    /// True when the second difference of the map along x or y exceeds
    /// `limit`: interpolation would put sub-samples that far off.
    pub fn bends(&self, x: i64, y: i64, centre: [f64; 2], ev: f32, limit: f64) -> bool {
        [(1, 0), (0, 1)].iter().any(|&(dx, dy)| {
            match (
                self.consistent(x + dx, y + dy, ev),
                self.consistent(x - dx, y - dy, ev),
            ) {
                (Some(f), Some(b)) => {
                    let d2 = [f[0] + b[0] - 2.0 * centre[0], f[1] + b[1] - 2.0 * centre[1]];
                    (d2[0] * d2[0] + d2[1] * d2[1]).sqrt() > limit
                }
                _ => false,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn film(w: u32, h: u32, f: impl Fn(i64, i64) -> Option<([f32; 2], f32)>) -> Film {
        let mut film = Film::new(w, h);
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let i = (y * w as i64 + x) as usize;
                if let Some((hit, e)) = f(x, y) {
                    film.u[i] = hit[0];
                    film.v[i] = hit[1];
                    film.events[i] = e;
                }
            }
        }
        film
    }

    /// The selects give the checked lookups' Jacobian, bit for bit, on a
    /// film of three pieces and holes without a hit.
    #[test]
    fn inside_jacobian_matches_the_checked_one() {
        let f = film(24, 20, |x, y| {
            let k = crate::phantom::mix64((y * 24 + x) as u64);
            let u = |j| crate::phantom::uniform(k, j) as f32;
            (u(0) > 0.2).then(|| ([x as f32 + u(1), 0.5 * y as f32 - u(2)], (k % 3) as f32))
        });
        let m = HitMap::new(&f);
        let mut cases = [0usize; 4];
        for y in 1..19 {
            for x in 1..23 {
                let Some((hit, ev)) = m.at(x, y) else {
                    continue;
                };
                let (fast, checked) =
                    (m.jacobian(x, y, hit, ev), m.jacobian_checked(x, y, hit, ev));
                assert_eq!(fast, checked, "({x}, {y})");
                let one = |d: i64| {
                    let on = |i: i64, j: i64| m.consistent(i, j, ev).is_some();
                    (on(x + d, y) as usize) + 2 * (on(x - d, y) as usize)
                };
                cases[one(1)] += 1;
            }
        }
        assert!(cases.iter().all(|&c| c > 10), "cases {cases:?}");
    }

    #[test]
    fn jacobian_respects_pieces() {
        // u = 2x + y, v = -y on events 0 for x < 3; a different piece beyond.
        let f = film(6, 4, |x, y| {
            let h = [(2 * x + y) as f32, -y as f32];
            Some((h, if x < 3 { 0.0 } else { 2.0 }))
        });
        let m = HitMap::new(&f);
        let j = m.jacobian(1, 1, [3.0, -1.0], 0.0);
        assert_eq!(j.dx, Some([2.0, 0.0]));
        assert_eq!(j.dy, Some([1.0, -1.0]));
        // At x = 2 the right neighbour is on the other piece: one-sided.
        let j = m.jacobian(2, 1, [5.0, -1.0], 0.0);
        assert_eq!(j.dx, Some([2.0, 0.0]));
        assert_eq!(
            m.neighbour(3, 1, Some(0.0)),
            Neighbour::Other([7.0, -1.0], 2.0)
        );
        assert_eq!(m.neighbour(-1, 1, Some(0.0)), Neighbour::Same);
        assert_eq!(j.apply([5.0, -1.0], 0.5, -0.5), [5.5, -0.5]);
    }
}
