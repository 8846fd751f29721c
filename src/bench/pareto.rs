//! The Pareto front of (time, error): the configurations worth choosing.
//!
//! A configuration is dominated when another is at least as fast and at least
//! as accurate, and strictly better in one of the two; nobody should pick a
//! dominated one. The front is what the time-vs-error plot connects.

/// Indices of the non-dominated points (both coordinates minimised), sorted
/// by the first coordinate (then the second). Points with a NaN coordinate
/// take no part; identical points are all kept (neither beats the other).
pub fn front(points: &[(f64, f64)]) -> Vec<usize> {
    let valid = |p: &(f64, f64)| !p.0.is_nan() && !p.1.is_nan();
    let mut out: Vec<usize> = (0..points.len())
        .filter(|&i| valid(&points[i]))
        .filter(|&i| {
            let p = points[i];
            !points
                .iter()
                .any(|q| valid(q) && q.0 <= p.0 && q.1 <= p.1 && (q.0 < p.0 || q.1 < p.1))
        })
        .collect();
    out.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_only_undominated_points_in_time_order() {
        // (time, error)
        let p = [
            (10.0, 1.0), // 0: fast, inaccurate: front
            (20.0, 0.5), // 1: front
            (25.0, 0.6), // 2: dominated by 1
            (40.0, 0.1), // 3: front
            (50.0, 0.1), // 4: dominated by 3 (slower, same error)
            (5.0, 2.0),  // 5: fastest: front
        ];
        assert_eq!(front(&p), vec![5, 0, 1, 3]);
    }

    #[test]
    fn edge_cases() {
        assert!(front(&[]).is_empty());
        assert_eq!(front(&[(1.0, 1.0)]), vec![0]);
        // Identical points both stay; a NaN point is ignored and dominates nothing.
        assert_eq!(front(&[(1.0, 1.0), (1.0, 1.0)]), vec![0, 1]);
        assert_eq!(front(&[(f64::NAN, 0.0), (2.0, 3.0)]), vec![1]);
        assert_eq!(front(&[(1.0, f64::NAN)]), Vec::<usize>::new());
        // One point best in both: the front is that point alone.
        assert_eq!(front(&[(3.0, 3.0), (1.0, 1.0), (2.0, 5.0)]), vec![1]);
        // Infinite error is dominated by any finite one at equal or lower time.
        assert_eq!(front(&[(1.0, f64::INFINITY), (1.0, 2.0)]), vec![1]);
    }
}
