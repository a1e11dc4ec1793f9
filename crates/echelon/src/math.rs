//! Small numerical helpers shared by the references and the odometry.

/// `sin(x)/x`, accurate near 0 (where it uses its Taylor series).
#[inline]
pub(crate) fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_and_closed_forms_agree_at_the_switch() {
        for x in [0.99e-4, 1.01e-4, -1.01e-4] {
            assert!((sinc(x) - x.sin() / x).abs() < 1e-15);
        }
        assert_eq!(sinc(0.0), 1.0);
    }
}
