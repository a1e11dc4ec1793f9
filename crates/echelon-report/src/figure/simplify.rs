//! Thinning long series to what the pixels can show (Ramer–Douglas–Peucker).

/// Indices of the points Ramer–Douglas–Peucker keeps at tolerance `eps` (in the
/// points' own units); the first and last are always kept.
pub fn simplify(points: &[(f64, f64)], eps: f64) -> Vec<usize> {
    let n = points.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((a, b)) = stack.pop() {
        if b <= a + 1 {
            continue;
        }
        let (ax, ay) = points[a];
        let (bx, by) = points[b];
        let (dx, dy) = (bx - ax, by - ay);
        let len = dx.hypot(dy);
        let mut worst = (0.0, a);
        for (i, &(px, py)) in points.iter().enumerate().take(b).skip(a + 1) {
            let d = if len > 0.0 {
                ((px - ax) * dy - (py - ay) * dx).abs() / len
            } else {
                (px - ax).hypot(py - ay)
            };
            if d > worst.0 {
                worst = (d, i);
            }
        }
        if worst.0 > eps {
            keep[worst.1] = true;
            stack.push((a, worst.1));
            stack.push((worst.1, b));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplify_keeps_corners_and_drops_collinear_points() {
        let mut pts: Vec<(f64, f64)> = (0..=100).map(|i| (f64::from(i), 0.0)).collect();
        pts.extend((1..=100).map(|i| (100.0, f64::from(i))));
        let kept = simplify(&pts, 0.25);
        assert_eq!(kept, vec![0, 100, 200]);
    }

    #[test]
    fn simplify_stays_within_tolerance() {
        let pts: Vec<(f64, f64)> = (0..2000)
            .map(|i| {
                let t = f64::from(i) * 0.01;
                (t * 40.0, (t * 3.0).sin() * 100.0)
            })
            .collect();
        let kept = simplify(&pts, 0.25);
        assert!(kept.len() < pts.len() / 4, "{}", kept.len());
        // Every dropped point is within 0.25 of the kept polyline segment around it.
        for w in kept.windows(2) {
            let (a, b) = (pts[w[0]], pts[w[1]]);
            for p in &pts[w[0]..w[1]] {
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let d = ((p.0 - a.0) * dy - (p.1 - a.1) * dx).abs() / dx.hypot(dy);
                assert!(d <= 0.25 + 1e-12);
            }
        }
    }
}
