//! Empty-space skipping by distance: beyond the paper's octree.
//!
//! Each cell stores its chessboard (L∞) distance, in cells, to the nearest
//! tagged cell (0 for a tagged cell, saturating at 255). A ray in a cell at
//! distance `d > 0` knows the cube of radius `d - 1` around it holds no tagged
//! cell, and jumps to where it leaves that cube in one step. The octree can
//! only skip *aligned* blocks, which shrink to single cells next to a surface
//! whatever the ray's direction; the distance cube is centred on the ray.
//!
//! The field is exact: two raster passes with the full 26-neighbourhood and
//! unit weights compute the chessboard distance transform exactly (Rosenfeld &
//! Pfaltz 1966, in 3-D).

use crate::classify::Tags;

#[derive(Clone, Debug)]
pub struct Proximity {
    cells: [usize; 3],
    dist: Vec<u8>,
}

impl Proximity {
    pub fn build(tags: &Tags) -> Proximity {
        let cells = tags.cells;
        let [nx, ny, nz] = cells;
        let n = nx * ny * nz;
        let mut d: Vec<u8> = (0..n)
            .map(|i| if tags.get_index(i) { 0 } else { 255 })
            .collect();
        let idx = |x: usize, y: usize, z: usize| x + nx * (y + ny * z);
        // Forward: the 13 neighbours before (x, y, z) in raster order.
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let i = idx(x, y, z);
                    if d[i] == 0 {
                        continue;
                    }
                    let mut m = d[i];
                    for dz in -1i64..=0 {
                        for dy in -1i64..=1 {
                            for dx in -1i64..=1 {
                                if dz == 0 && (dy > 0 || (dy == 0 && dx >= 0)) {
                                    continue;
                                }
                                let (xx, yy, zz) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                                if xx < 0 || yy < 0 || zz < 0 || xx >= nx as i64 || yy >= ny as i64
                                {
                                    continue;
                                }
                                m = m.min(
                                    d[idx(xx as usize, yy as usize, zz as usize)].saturating_add(1),
                                );
                            }
                        }
                    }
                    d[i] = m;
                }
            }
        }
        // Backward: the 13 neighbours after it.
        for z in (0..nz).rev() {
            for y in (0..ny).rev() {
                for x in (0..nx).rev() {
                    let i = idx(x, y, z);
                    if d[i] == 0 {
                        continue;
                    }
                    let mut m = d[i];
                    for dz in 0i64..=1 {
                        for dy in -1i64..=1 {
                            for dx in -1i64..=1 {
                                if dz == 0 && (dy < 0 || (dy == 0 && dx <= 0)) {
                                    continue;
                                }
                                let (xx, yy, zz) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                                if xx < 0
                                    || yy < 0
                                    || xx >= nx as i64
                                    || yy >= ny as i64
                                    || zz >= nz as i64
                                {
                                    continue;
                                }
                                m = m.min(
                                    d[idx(xx as usize, yy as usize, zz as usize)].saturating_add(1),
                                );
                            }
                        }
                    }
                    d[i] = m;
                }
            }
        }
        Proximity { cells, dist: d }
    }

    /// Chessboard distance of cell `c` (in range) to the nearest tagged cell.
    #[inline(always)]
    pub fn get(&self, c: [i64; 3]) -> u8 {
        self.dist[c[0] as usize + self.cells[0] * (c[1] as usize + self.cells[1] * c[2] as usize)]
    }

    pub fn bytes(&self) -> usize {
        self.dist.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force_chessboard_distance() {
        let cells = [9usize, 7, 8];
        let n = cells.iter().product::<usize>();
        let on: Vec<usize> = (0..n).filter(|i| (i * 2654435761usize) % 97 < 2).collect();
        let mut flags = vec![0u8; n];
        for &i in &on {
            flags[i] = 1;
        }
        let tags = Tags::from_chunks(cells, vec![flags]);
        let p = Proximity::build(&tags);
        for z in 0..cells[2] {
            for y in 0..cells[1] {
                for x in 0..cells[0] {
                    let want = on
                        .iter()
                        .map(|&i| {
                            let (qx, qy, qz) = (i % 9, i / 9 % 7, i / 63);
                            (x.abs_diff(qx)).max(y.abs_diff(qy)).max(z.abs_diff(qz))
                        })
                        .min()
                        .unwrap()
                        .min(255) as u8;
                    assert_eq!(p.get([x as i64, y as i64, z as i64]), want, "({x},{y},{z})");
                }
            }
        }
    }
}
