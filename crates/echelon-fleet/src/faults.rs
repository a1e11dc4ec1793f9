//! Fault injection on what a robot receives (`--loss`, `--delay`, `--outage`),
//! seeded and reproducible: the same seed and the same arrivals give the same
//! drop pattern.

use echelon::rng::SplitMix64;

/// What the injector does.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FaultSpec {
    /// Probability in `[0, 1]` that a message is dropped.
    pub loss: f64,
    /// Extra delay added to every message, fleet s.
    pub delay: f64,
    /// `(start, length)`, fleet s: everything arriving in `[start, start + length)` is dropped.
    pub outage: Option<(f64, f64)>,
    /// Seed of the drop pattern.
    pub seed: u64,
}

impl FaultSpec {
    /// Whether it injects anything.
    pub fn is_active(&self) -> bool {
        self.loss > 0.0 || self.delay > 0.0 || self.outage.is_some()
    }
}

/// What happens to one arriving message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Dropped by `--loss`.
    Lost,
    /// Dropped by `--outage`.
    Outage,
    /// Delivered at this fleet time.
    DeliverAt(f64),
}

/// Applies a [`FaultSpec`] to arrivals.
#[derive(Debug, Clone)]
pub struct FaultInjector {
    spec: FaultSpec,
    rng: SplitMix64,
}

impl FaultInjector {
    /// An injector; `stream` (e.g. the agent number) decorrelates robots that
    /// share a seed.
    pub fn new(spec: FaultSpec, stream: u64) -> Self {
        FaultInjector {
            spec,
            rng: SplitMix64::new(spec.seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03)),
        }
    }

    /// The verdict for a message arriving at fleet time `t`. One random draw
    /// per arrival, whatever the verdict, so the pattern depends only on the
    /// seed and the arrival count.
    pub fn admit(&mut self, t: f64) -> Verdict {
        let draw = self.rng.next_f64();
        if let Some((start, len)) = self.spec.outage
            && t >= start
            && t < start + len
        {
            return Verdict::Outage;
        }
        if draw < self.spec.loss {
            return Verdict::Lost;
        }
        Verdict::DeliverAt(t + self.spec.delay)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(seed: u64, loss: f64) -> Vec<bool> {
        let mut f = FaultInjector::new(
            FaultSpec {
                loss,
                seed,
                ..FaultSpec::default()
            },
            1,
        );
        (0..10_000)
            .map(|i| matches!(f.admit(i as f64 * 0.01), Verdict::Lost))
            .collect()
    }

    #[test]
    fn same_seed_same_pattern_and_the_rate_is_right() {
        let a = pattern(42, 0.2);
        assert_eq!(a, pattern(42, 0.2));
        assert_ne!(a, pattern(43, 0.2));
        let rate = a.iter().filter(|&&l| l).count() as f64 / a.len() as f64;
        // Binomial(10000, 0.2): σ = 0.004; 5σ.
        assert!((rate - 0.2).abs() < 0.02, "{rate}");
        assert!(pattern(1, 0.0).iter().all(|l| !l));
    }

    #[test]
    fn outage_and_delay() {
        let mut f = FaultInjector::new(
            FaultSpec {
                delay: 0.05,
                outage: Some((1.0, 3.0)),
                ..FaultSpec::default()
            },
            2,
        );
        assert_eq!(f.admit(0.5), Verdict::DeliverAt(0.55));
        assert_eq!(f.admit(1.0), Verdict::Outage);
        assert_eq!(f.admit(3.99), Verdict::Outage);
        assert_eq!(f.admit(4.0), Verdict::DeliverAt(4.05));
    }

    #[test]
    fn uniform_draws_are_in_range() {
        let mut r = SplitMix64::new(7);
        for _ in 0..1000 {
            let x = r.next_f64();
            assert!((0.0..1.0).contains(&x));
        }
    }
}
