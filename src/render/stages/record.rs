//! Stage 6: rays that left the volume travel straight to the backdrop; record
//! where they land (the hit-position image) and what colour they see.

use super::super::context::Ctx;
use super::super::packet::{Fate, Rays};
use super::super::tile::TileOut;
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;
use crate::scene::Backdrop;
use crate::simd::Isa;

/// Rays per run of [`backdrop_hits`]: one AVX-512 vector of `f64`.
const RUN: usize = 8;

/// Records every ray of `input`: its hit position (pixel-centre rays) and,
/// where `out` holds colours, its weighted backdrop colour (skipped when a
/// post stage colours the film from the hit image: single-thread record
/// stage, sphere 6.0 / 5.9 → 3.3 / 3.2 ms, teapot 6.4 / 6.0 → 3.4 / 3.5 ms).
/// The backdrop hits of a run of rays are computed in vector lanes
/// ([`backdrop_hits`]).
pub fn record<T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    input: &[u32],
    out: &mut TileOut,
    c: &mut Counters,
) {
    crate::with_isa!(Isa::current(), _L, _M => record_runs(ctx, rays, input, out, c))
}

#[inline(always)]
fn record_runs<T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    input: &[u32],
    out: &mut TileOut,
    c: &mut Counters,
) {
    let backdrop = &ctx.scene.backdrop;
    for run in input.chunks(RUN) {
        // Lanes past the run's end repeat its first ray; their results are
        // not read.
        // (Plain loops: `array::from_fn` here compiled to calls through its
        // closure machinery, most of the stage's time.)
        let (mut o, mut d) = ([[0.0; RUN]; 3], [[0.0; RUN]; 3]);
        for l in 0..RUN {
            let i = run[if l < run.len() { l } else { 0 }] as usize;
            for a in 0..3 {
                o[a][l] = rays.org[a][i];
                d[a][l] = rays.dir[a][i];
            }
        }
        let hits = backdrop_hits(backdrop, &o, &d);
        for (l, &r) in run.iter().enumerate() {
            let i = r as usize;
            let hit = match rays.fate[i] {
                Fate::Escaped => hits.landing(l, c),
                Fate::Terminated => None,
                Fate::Active => {
                    c.undefined += 1;
                    None
                }
            };
            let ray = Recorded {
                slot: rays.slot[i],
                weight: rays.weight[i],
                centre: rays.centre[i],
                events: rays.events[i],
            };
            write(ctx, hit, ray, out);
        }
    }
}

/// Records the pixel-centre primary rays of lanes `lanes` of a run (origin
/// `org`, directions `dir[axis][lane]`, lane `l` writing output slot
/// `slot + l`) that go straight to the backdrop from the camera: what
/// [`record`] writes for them, without their ever entering the packet (see
/// [`super::entry`]). Inlined into the entry stage, whose instruction set
/// it then runs in.
#[inline(always)]
pub fn record_straight<T: Coefficient>(
    ctx: &Ctx<T>,
    org: [f64; 3],
    dir: &[[f64; RUN]; 3],
    lanes: u8,
    slot: u32,
    out: &mut TileOut,
    c: &mut Counters,
) {
    let o = org.map(|v| [v; RUN]);
    let hits = backdrop_hits(&ctx.scene.backdrop, &o, dir);
    for l in (0..RUN).filter(|&l| lanes >> l & 1 == 1) {
        let ray = Recorded {
            slot: slot + l as u32,
            weight: 1.0,
            centre: true,
            events: 0,
        };
        write(ctx, hits.landing(l, c), ray, out);
    }
}

/// What the film needs of a recorded ray besides its landing point.
#[derive(Clone, Copy)]
struct Recorded {
    /// Its pixel's output slot in the tile.
    slot: u32,
    weight: f32,
    /// The pixel-centre ray, which writes the hit-position image.
    centre: bool,
    events: u32,
}

/// Writes a ray's landing point `hit` (none: it stopped, or missed the
/// backdrop) into the tile's output: its colour's share, and for the
/// pixel-centre ray the hit-position image.
#[inline(always)]
fn write<T: Coefficient>(ctx: &Ctx<T>, hit: Option<(f64, f64)>, ray: Recorded, out: &mut TileOut) {
    if out.records_colours() {
        let color = match hit {
            Some((u, v)) => ctx.scene.backdrop.color(u, v),
            None => ctx.scene.background,
        };
        out.add_color(ray.slot, ray.weight, color);
    }
    if ray.centre {
        let (u, v) = hit.unwrap_or((f64::NAN, f64::NAN));
        out.set_hit(ray.slot, u as f32, v as f32, ray.events as f32);
    }
}

/// Where a ray meets the backdrop, if it does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum HitState {
    /// A non-finite origin or direction.
    Undefined,
    /// Parallel to the backdrop, or pointing away from it.
    Missed,
    Hit,
}

/// The backdrop coordinates of a run of rays (origins `o`, directions `d`).
struct Hits {
    u: [f64; RUN],
    v: [f64; RUN],
    state: [HitState; RUN],
}

impl Hits {
    /// Where lane `l` lands, counting the rays that do not.
    #[inline(always)]
    fn landing(&self, l: usize, c: &mut Counters) -> Option<(f64, f64)> {
        match self.state[l] {
            HitState::Undefined => {
                c.undefined += 1;
                None
            }
            HitState::Missed => {
                c.missed_backdrop += 1;
                None
            }
            HitState::Hit => Some((self.u[l], self.v[l])),
        }
    }
}

/// [`Backdrop::hit`] for a run of rays in vector lanes: the same operations
/// in the same order for every lane (the dot products left to right, no
/// fused multiply-adds), so bitwise what each ray alone gives (tested),
/// with the run's divisions in one vector.
#[inline(always)]
fn backdrop_hits(b: &Backdrop, o: &[[f64; RUN]; 3], d: &[[f64; RUN]; 3]) -> Hits {
    let (c, n) = (b.center.to_array(), b.normal.to_array());
    let (ua, va) = (b.u_axis.to_array(), b.v_axis.to_array());
    let mut h = Hits {
        u: [0.0; RUN],
        v: [0.0; RUN],
        state: [HitState::Missed; RUN],
    };
    for l in 0..RUN {
        let (o, d) = ([o[0][l], o[1][l], o[2][l]], [d[0][l], d[1][l], d[2][l]]);
        let finite = o[0].is_finite()
            & o[1].is_finite()
            & o[2].is_finite()
            & d[0].is_finite()
            & d[1].is_finite()
            & d[2].is_finite();
        let denom = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
        let t = ((c[0] - o[0]) * n[0] + (c[1] - o[1]) * n[1] + (c[2] - o[2]) * n[2]) / denom;
        let p = [
            o[0] + t * d[0] - c[0],
            o[1] + t * d[1] - c[1],
            o[2] + t * d[2] - c[2],
        ];
        h.u[l] = p[0] * ua[0] + p[1] * ua[1] + p[2] * ua[2];
        h.v[l] = p[0] * va[0] + p[1] * va[1] + p[2] * va[2];
        let meets = denom != 0.0 && denom.is_finite() && t > 0.0 && t.is_finite();
        h.state[l] = if !finite {
            HitState::Undefined
        } else if meets {
            HitState::Hit
        } else {
            HitState::Missed
        };
    }
    h
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::phantom::{mix64, uniform};
    use crate::scene::Pattern;

    /// The lanes give what [`Backdrop::hit`] gives each ray, bit for bit,
    /// for rays towards, along and away from the backdrop, and non-finite
    /// ones.
    #[test]
    fn lanes_hit_the_backdrop_as_each_ray_does() {
        let b = Backdrop {
            center: DVec3::new(1.5, -2.0, 40.0),
            normal: DVec3::new(0.1, -0.2, -1.0).normalize(),
            u_axis: DVec3::new(1.0, 0.0, 0.1).normalize(),
            v_axis: DVec3::new(0.0, 1.0, -0.2).normalize(),
            pattern: Pattern::Checker {
                size: 2.0,
                colors: [[1.0; 3], [0.0; 3]],
            },
        };
        let odd = [f64::NAN, f64::INFINITY, 0.0, -0.0, 1e300];
        let mut seen = [0usize; 3];
        for k in 0..3000u64 {
            let r = |j: u64| 2.0 * uniform(mix64(k), j) - 1.0;
            let mut o = [[0.0; RUN]; 3];
            let mut d = [[0.0; RUN]; 3];
            for l in 0..RUN {
                let j = 8 * l as u64;
                let mut dl = DVec3::new(r(j), r(j + 1), r(j + 2) + 0.5);
                if k % 5 == 1 && l == 2 {
                    // Along the backdrop.
                    dl = b.u_axis;
                }
                let mut ol = DVec3::new(10.0 * r(j + 3), 10.0 * r(j + 4), 20.0 * r(j + 5));
                if k % 7 == 3 && l == 5 {
                    ol[(k % 3) as usize] = odd[(k / 7 % 5) as usize];
                }
                if k % 11 == 4 && l == 6 {
                    dl[(k % 3) as usize] = odd[(k / 11 % 5) as usize];
                }
                for a in 0..3 {
                    o[a][l] = ol[a];
                    d[a][l] = dl[a];
                }
            }
            let h = backdrop_hits(&b, &o, &d);
            for l in 0..RUN {
                let (ol, dl) = (
                    DVec3::new(o[0][l], o[1][l], o[2][l]),
                    DVec3::new(d[0][l], d[1][l], d[2][l]),
                );
                let want = if !(ol.is_finite() && dl.is_finite()) {
                    (HitState::Undefined, None)
                } else {
                    match b.hit(ol, dl) {
                        Some((u, v)) => (HitState::Hit, Some((u.to_bits(), v.to_bits()))),
                        None => (HitState::Missed, None),
                    }
                };
                let got = match h.state[l] {
                    HitState::Hit => (HitState::Hit, Some((h.u[l].to_bits(), h.v[l].to_bits()))),
                    s => (s, None),
                };
                assert_eq!(got, want, "{k}/{l}: {ol:?} {dl:?}");
                seen[want.0 as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 50), "{seen:?}");
    }
}
