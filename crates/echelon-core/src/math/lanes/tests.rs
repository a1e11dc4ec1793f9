use super::*;

type L = Lanes<4>;

/// Distance in units in the last place of `want` (at least of 2⁻⁵³).
fn ulps(got: f64, want: f64) -> f64 {
    let unit = f64::EPSILON * want.abs().max(1e-300);
    (got - want).abs() / unit
}

fn sample(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

#[test]
fn a_small_turn_gives_the_sine_and_cosine_of_the_turned_angle() {
    // θ from the start sin_cos, δ up to the limit in both directions.
    let thetas = sample(11, 4_000);
    let deltas = sample(12, 4_000);
    let mut worst = 0.0f64;
    for (tc, dc) in thetas.chunks_exact(4).zip(deltas.chunks_exact(4)) {
        let theta = L::from_slice(tc) * 200.0 - 100.0;
        let mut delta = (L::from_slice(dc) * 2.0 - 1.0) * 0.0499;
        delta.0[3] *= 1e-6;
        delta.0[2] = 0.0;
        let (s, c) = theta.sin_cos();
        let (ts, tc) = delta.sin_cos_turned(s, c).expect("every |δ| < 0.05");
        for i in 0..4 {
            let (t, d) = (theta.0[i], delta.0[i]);
            let (ws, wc) = (t + d).sin_cos();
            // Absolute error, from the rounding of θ + δ in the state
            // (half an ulp of it) and of the arithmetic (a few 2⁻⁵³).
            let allowed = 0.5 * (t + d).abs() * f64::EPSILON + 4.0 * f64::EPSILON;
            let err = (ts.0[i] - ws).abs().max((tc.0[i] - wc).abs());
            worst = worst.max(err / allowed);
            assert!(err <= allowed, "θ = {t}, δ = {d}: off by {err:e}");
        }
    }
    assert!(worst > 0.0);
    // Where θ + δ is exact (both dyadic), within 3 units of 2⁻⁵³ of libm.
    for k in 0..200 {
        let theta = L::splat(f64::from(k) * 0.125 - 12.0);
        let delta = L::from_slice(&[0.03125, -0.046875, 2f64.powi(-20), -0.0]);
        let (s, c) = theta.sin_cos();
        let (ts, tc) = delta.sin_cos_turned(s, c).unwrap();
        for i in 0..4 {
            let (ws, wc) = (theta.0[i] + delta.0[i]).sin_cos();
            assert!((ts.0[i] - ws).abs() <= 3.0 * f64::EPSILON);
            assert!((tc.0[i] - wc).abs() <= 3.0 * f64::EPSILON);
        }
    }
    // A large or non-finite turn in any lane: the caller's full sin_cos.
    let (s, c) = L::splat(1.0).sin_cos();
    for bad in [0.05, -0.06, 3.0, f64::NAN, f64::INFINITY] {
        let delta = L::from_slice(&[0.001, bad, 0.0, 0.0]);
        assert!(delta.sin_cos_turned(s, c).is_none(), "δ = {bad}");
    }
}

#[test]
fn sin_cos_is_within_two_ulp_of_libm() {
    let mut worst = 0.0f64;
    let mut xs: Vec<f64> = Vec::new();
    for (scale, seed) in [(1.0, 1), (10.0, 2), (1e3, 3), (1e6, 4), (5e8, 5)] {
        xs.extend(sample(seed, 20_000).iter().map(|u| (2.0 * u - 1.0) * scale));
    }
    // Quadrant boundaries and awkward points.
    for k in -40..=40 {
        let b = k as f64 * std::f64::consts::FRAC_PI_4;
        xs.extend([b, b.next_up(), b.next_down()]);
    }
    xs.extend([0.0, -0.0, 1e-300, -1e-300, 1e-8, 355.0, 103_993.0]);
    for chunk in xs.chunks_exact(4) {
        let x = L::from_slice(chunk);
        let (s, c) = x.sin_cos();
        for i in 0..4 {
            let (ws, wc) = x.0[i].sin_cos();
            // Absolute error against |·| ≤ 1 where the value is tiny.
            let es = ulps(s.0[i], ws).min((s.0[i] - ws).abs() / f64::EPSILON);
            let ec = ulps(c.0[i], wc).min((c.0[i] - wc).abs() / f64::EPSILON);
            worst = worst.max(es).max(ec);
            assert!(es <= 2.0 && ec <= 2.0, "x = {}: {es} / {ec} ulp", x.0[i]);
        }
    }
    assert!(
        worst > 0.0,
        "the polynomial is not libm: some rounding differs"
    );
}

#[test]
fn sin_cos_of_huge_or_non_finite_lanes_falls_back() {
    let x = L::from_slice(&[1e12, f64::INFINITY, f64::NAN, 0.5]);
    let (s, c) = x.sin_cos();
    assert_eq!((s.0[0], c.0[0]), 1e12f64.sin_cos());
    assert!(s.0[1].is_nan() && c.0[1].is_nan() && s.0[2].is_nan());
    assert!((s.0[3] - 0.5f64.sin()).abs() <= 2.0 * f64::EPSILON);
}

#[test]
fn atan2_is_within_two_ulp_of_libm_in_every_quadrant() {
    let u = sample(7, 40_000);
    let mut pairs: Vec<(f64, f64)> = u
        .chunks_exact(2)
        .map(|p| {
            let scale = 10f64.powf(8.0 * p[1] - 4.0);
            ((2.0 * p[0] - 1.0) * scale, (2.0 * p[1] - 1.0) * 3.0)
        })
        .collect();
    for &(y, x) in &[
        (0.0, 1.0),
        (0.0, -1.0),
        (-0.0, -1.0),
        (1.0, 0.0),
        (-1.0, 0.0),
        (0.0, 0.0),
        (-0.0, -0.0),
        (1.0, 1.0),
        (-1.0, -1.0),
        (0.66, 1.0),
        (2.414_213_562_373_095, 1.0),
        (1e-300, 1.0),
        (1.0, 1e-300),
        (3.0, -1e-20),
    ] {
        pairs.push((y, x));
    }
    while !pairs.len().is_multiple_of(4) {
        pairs.push((1.0, 2.0));
    }
    for chunk in pairs.chunks_exact(4) {
        let y = L::from_slice(&chunk.iter().map(|p| p.0).collect::<Vec<_>>());
        let x = L::from_slice(&chunk.iter().map(|p| p.1).collect::<Vec<_>>());
        let a = L::atan2(y, x);
        for i in 0..4 {
            let want = y.0[i].atan2(x.0[i]);
            let e = ulps(a.0[i], want);
            assert!(
                e <= 2.0 || (a.0[i] - want).abs() <= 1e-300,
                "atan2({}, {}) = {} vs {want}: {e} ulp",
                y.0[i],
                x.0[i],
                a.0[i]
            );
            assert_eq!(
                a.0[i].is_sign_negative(),
                want.is_sign_negative(),
                "sign of atan2({}, {})",
                y.0[i],
                x.0[i]
            );
        }
    }
}

#[test]
fn lane_arithmetic_is_scalar_arithmetic() {
    let a = L::from_slice(&[1.5, -2.25, 1e-310, 3.0]);
    let b = L::from_slice(&[0.1, 7.0, 2.0, -0.0]);
    for i in 0..4 {
        assert_eq!((a + b).0[i], a.0[i] + b.0[i]);
        assert_eq!((a * b).0[i].to_bits(), (a.0[i] * b.0[i]).to_bits());
        assert_eq!((a / b).0[i].to_bits(), (a.0[i] / b.0[i]).to_bits());
        assert_eq!((a - 0.3).0[i], a.0[i] - 0.3);
        assert_eq!(a.max(b).0[i], a.0[i].max(b.0[i]));
        assert_eq!(a.min(b).0[i], a.0[i].min(b.0[i]));
    }
    let m = a.lt(b);
    assert_eq!(L::select(m, a, b).0, [b.0[0], a.0[1], a.0[2], b.0[3]]);
    assert_eq!(
        L::from_slice(&[1.0, f64::NAN, f64::INFINITY, -0.0])
            .finite()
            .0,
        [u64::MAX, 0, 0, u64::MAX]
    );
}
