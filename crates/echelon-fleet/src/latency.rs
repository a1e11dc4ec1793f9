//! Measured latency: the delay from a sample's sender timestamp to its
//! receipt, in a fixed-memory log-linear histogram.
//!
//! **The clock.** Every fleet publisher stamps its samples with the Zenoh
//! sample timestamp ([`zenoh::Session::new_timestamp`]: the host's
//! `CLOCK_REALTIME`, through the session's HLC when it has one); the
//! receiver reads `CLOCK_REALTIME` when Zenoh hands it the sample (in the
//! subscription callback) and records the difference ([`delay_ns`]). On
//! loopback every process reads the same host clock, so the difference is
//! the true delay (publication, routing, delivery to the callback), to the
//! clock's resolution. Across machines it is only as good as the clocks'
//! synchronisation (PTP or NTP: the error is the offset between the two
//! hosts, which can make a delay negative); such a sample is recorded as 0
//! and counted as `early`. A sample without a timestamp (e.g. from a ROS 2
//! node that does not stamp) is counted as `unstamped`, not recorded.
//!
//! **The histogram** ([`Histogram`]) holds delays in nanoseconds in buckets
//! of width 1 below 128 ns, then 64 buckets per power of two up to
//! 2⁴⁰ ns (≈ 18 min; larger delays land in the last bucket, the exact
//! maximum is kept apart). A quantile is the middle of the bucket holding
//! the sample of nearest rank `⌈p·n⌉`, clamped to the exact minimum and
//! maximum: within a relative error of 1/128 (0.8 %) of that sample. It is
//! one allocation made when it is created; recording never allocates.

use serde::{Deserialize, Serialize};

/// Values below this are their own bucket.
const EXACT: u64 = 128;
/// Buckets per power of two above [`EXACT`].
const SUB: u64 = 64;
/// Largest exponent kept apart: values of 2^`TOP` ns and more share the last bucket.
const TOP: u32 = 40;
/// Number of buckets.
const BUCKETS: usize = (EXACT + (TOP as u64 - 7) * SUB) as usize;

/// The bound on a quantile's relative error.
pub const RELATIVE_ERROR: f64 = 1.0 / 128.0;

/// A fixed-memory histogram of non-negative integers (nanoseconds).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Histogram {
    counts: Buckets,
    count: u64,
    sum: u128,
    min: u64,
    max: u64,
}

/// A histogram's count per bucket ([`BUCKETS`] of them), shown by its
/// non-empty buckets only.
#[derive(Clone, PartialEq, Eq)]
struct Buckets(Box<[u64]>);

impl Buckets {
    /// The non-empty buckets as `(smallest value, count)`, smallest first.
    fn non_empty(&self) -> impl Iterator<Item = (u64, u64)> + '_ {
        self.0
            .iter()
            .enumerate()
            .filter(|&(_, &c)| c > 0)
            .map(|(i, &c)| (bounds(i).0, c))
    }
}

impl std::fmt::Debug for Buckets {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map().entries(self.non_empty()).finish()
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram::new()
    }
}

/// The bucket of `v`.
fn index(v: u64) -> usize {
    if v < EXACT {
        return v as usize;
    }
    let v = v.min((1u64 << TOP) - 1);
    let e = 63 - u64::from(v.leading_zeros()); // 7 ..= TOP - 1
    let m = v >> (e - 6); // 64 ..= 127
    (EXACT + (e - 7) * SUB + (m - SUB)) as usize
}

/// The smallest value of bucket `i` and the bucket's width.
fn bounds(i: usize) -> (u64, u64) {
    let i = i as u64;
    if i < EXACT {
        return (i, 1);
    }
    let e = 7 + (i - EXACT) / SUB;
    let m = SUB + (i - EXACT) % SUB;
    (m << (e - 6), 1 << (e - 6))
}

impl Histogram {
    /// An empty histogram (its one allocation).
    pub fn new() -> Histogram {
        Histogram {
            counts: Buckets(vec![0; BUCKETS].into_boxed_slice()),
            count: 0,
            sum: 0,
            min: u64::MAX,
            max: 0,
        }
    }

    /// Records `v` once.
    pub fn record(&mut self, v: u64) {
        self.record_n(v, 1);
    }

    /// Records `v` `n` times.
    pub fn record_n(&mut self, v: u64, n: u64) {
        if n == 0 {
            return;
        }
        self.counts.0[index(v)] += n;
        self.count += n;
        self.sum += u128::from(v) * u128::from(n);
        self.min = self.min.min(v);
        self.max = self.max.max(v);
    }

    /// Adds every value of `other`.
    pub fn merge(&mut self, other: &Histogram) {
        for (a, b) in self.counts.0.iter_mut().zip(other.counts.0.iter()) {
            *a += b;
        }
        self.count += other.count;
        self.sum += other.sum;
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
    }

    /// Values recorded.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The largest value recorded (0 if none).
    pub fn max(&self) -> u64 {
        self.max
    }

    /// The smallest value recorded (`None` if none).
    pub fn min(&self) -> Option<u64> {
        (self.count > 0).then_some(self.min)
    }

    /// The mean (0 if none).
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum as f64 / self.count as f64
        }
    }

    /// The `p` quantile (`0 < p ≤ 1`; 0 if empty): the value of nearest rank
    /// `⌈p·n⌉` within a relative error of [`RELATIVE_ERROR`]; `p = 1` is the
    /// exact maximum.
    pub fn quantile(&self, p: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        if p >= 1.0 {
            return self.max;
        }
        let rank = ((p * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0;
        for (i, &c) in self.counts.0.iter().enumerate() {
            seen += c;
            if seen >= rank {
                let (lower, width) = bounds(i);
                return (lower + (width - 1) / 2).clamp(self.min, self.max);
            }
        }
        self.max
    }

    /// The non-empty buckets as `(smallest value, count)`, smallest first.
    pub fn buckets(&self) -> Vec<(u64, u64)> {
        self.counts.non_empty().collect()
    }
}

/// What a process reports of the delays it measured (seconds).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatencyReport {
    /// Samples whose delay was recorded.
    pub count: u64,
    /// Samples that carried no sender timestamp (not recorded).
    #[serde(default)]
    pub unstamped: u64,
    /// Samples stamped after their receipt (clock offset; recorded as 0).
    #[serde(default)]
    pub early: u64,
    /// Median delay, s.
    pub p50: f64,
    /// 95th percentile, s.
    pub p95: f64,
    /// 99th percentile, s.
    pub p99: f64,
    /// Largest delay, s.
    pub max: f64,
    /// Mean delay, s.
    pub mean: f64,
    /// The histogram's non-empty buckets, `[smallest ns, count]` (to merge
    /// several processes' reports exactly); absent in per-key summaries.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub buckets: Vec<(u64, u64)>,
}

impl LatencyReport {
    /// The histogram its buckets describe (empty without buckets).
    pub fn histogram(&self) -> Histogram {
        let mut h = Histogram::new();
        for &(lower, n) in &self.buckets {
            h.record_n(lower, n);
        }
        h
    }
}

/// Delays measured on one stream (or a set of streams).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Latency {
    histogram: Histogram,
    unstamped: u64,
    early: u64,
}

/// Seconds of `ns` nanoseconds.
fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

impl Latency {
    /// Nothing measured yet.
    pub fn new() -> Latency {
        Latency::default()
    }

    /// Records one sample's delay ([`delay_ns`]: `None` if it was not stamped).
    pub fn record(&mut self, delay: Option<i64>) {
        match delay {
            None => self.unstamped += 1,
            Some(d) if d < 0 => {
                self.early += 1;
                self.histogram.record(0);
            }
            Some(d) => self.histogram.record(d as u64),
        }
    }

    /// Samples taken in (recorded or unstamped).
    pub fn samples(&self) -> u64 {
        self.histogram.count() + self.unstamped
    }

    /// The histogram of recorded delays, ns.
    pub fn histogram(&self) -> &Histogram {
        &self.histogram
    }

    /// Adds everything `other` measured.
    pub fn merge(&mut self, other: &Latency) {
        self.histogram.merge(&other.histogram);
        self.unstamped += other.unstamped;
        self.early += other.early;
    }

    /// A report with quantiles, and the buckets if `buckets`.
    pub fn report(&self, buckets: bool) -> LatencyReport {
        let h = &self.histogram;
        LatencyReport {
            count: h.count(),
            unstamped: self.unstamped,
            early: self.early,
            p50: secs(h.quantile(0.50)),
            p95: secs(h.quantile(0.95)),
            p99: secs(h.quantile(0.99)),
            max: secs(h.max()),
            mean: h.mean() * 1e-9,
            buckets: if buckets { h.buckets() } else { Vec::new() },
        }
    }

    /// The merge of several reports' buckets and counts (their exact
    /// maximum kept).
    pub fn of_reports<'a>(reports: impl IntoIterator<Item = &'a LatencyReport>) -> Latency {
        let mut l = Latency::new();
        for r in reports {
            l.histogram.merge(&r.histogram());
            if r.count > 0 {
                // The buckets hold lower bounds; the maximum is exact.
                let max = (r.max * 1e9).round() as u64;
                l.histogram.max = l.histogram.max.max(max);
            }
            l.unstamped += r.unstamped;
            l.early += r.early;
        }
        l
    }
}

/// The robot with the largest p99 delay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorstRobot {
    /// Agent number, from 1.
    pub agent: u64,
    /// Its delays (without buckets).
    pub latency: LatencyReport,
}

/// The delays of a whole fleet (`fleet-summary.json`).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FleetLatency {
    /// Every robot's leader-stream delays merged (reference → robot and
    /// robot → follower), without buckets.
    pub robots: LatencyReport,
    /// The robot with the largest p99.
    pub worst_robot: Option<WorstRobot>,
    /// The collector's (every sample it received).
    pub collector: LatencyReport,
}

impl FleetLatency {
    /// From each robot's `(agent, latency)` and the collector's latency.
    pub fn of<'a>(
        robots: impl IntoIterator<Item = (u32, &'a LatencyReport)>,
        collector: &LatencyReport,
    ) -> FleetLatency {
        let per_robot: Vec<(u64, &LatencyReport)> = robots
            .into_iter()
            .map(|(agent, l)| (u64::from(agent), l))
            .collect();
        let worst_robot = per_robot
            .iter()
            .filter(|(_, l)| l.count > 0)
            .max_by(|a, b| a.1.p99.total_cmp(&b.1.p99))
            .map(|(agent, l)| WorstRobot {
                agent: *agent,
                latency: LatencyReport {
                    buckets: Vec::new(),
                    ..(*l).clone()
                },
            });
        FleetLatency {
            robots: Latency::of_reports(per_robot.iter().map(|(_, l)| *l)).report(false),
            worst_robot,
            collector: collector.clone(),
        }
    }
}

/// The delay in ns from a sample's sender timestamp to `received_ns` (UNIX
/// ns, [`CLOCK_REALTIME`](std::time::SystemTime)), or `None` without a
/// timestamp.
pub fn delay_ns(stamp: Option<&zenoh::time::Timestamp>, received_ns: u64) -> Option<i64> {
    let sent = stamp?.get_time().as_nanos();
    Some(received_ns as i64 - sent as i64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The exact nearest-rank quantile of sorted values.
    fn exact(sorted: &[u64], p: f64) -> u64 {
        let n = sorted.len() as u64;
        let rank = ((p * n as f64).ceil() as u64).clamp(1, n);
        sorted[rank as usize - 1]
    }

    #[test]
    fn buckets_tile_the_range_in_order() {
        let mut next = 0;
        for i in 0..BUCKETS {
            let (lower, width) = bounds(i);
            assert_eq!(lower, next, "bucket {i}");
            assert_eq!(index(lower), i);
            assert_eq!(index(lower + width - 1), i);
            // Relative width at most 1/64 above the exact range.
            assert!(lower < EXACT || width * 64 <= lower, "bucket {i}");
            next = lower + width;
        }
        assert_eq!(next, 1 << TOP);
        assert_eq!(index(u64::MAX), BUCKETS - 1);
    }

    #[test]
    fn small_values_are_exact_and_empty_is_zero() {
        let mut h = Histogram::new();
        assert_eq!((h.quantile(0.5), h.max(), h.min()), (0, 0, None));
        for v in [3, 1, 2, 100] {
            h.record(v);
        }
        assert_eq!(h.quantile(0.25), 1);
        assert_eq!(h.quantile(0.5), 2);
        assert_eq!(h.quantile(0.75), 3);
        assert_eq!(h.quantile(0.99), 100);
        assert_eq!(h.quantile(1.0), 100);
        assert_eq!(h.mean(), 26.5);
    }

    #[test]
    fn latency_counts_unstamped_and_early_and_reports_seconds() {
        let mut l = Latency::new();
        l.record(None);
        l.record(Some(-5));
        l.record(Some(2_000_000));
        assert_eq!(l.samples(), 3);
        let r = l.report(true);
        assert_eq!((r.count, r.unstamped, r.early), (2, 1, 1));
        assert_eq!(r.max, 2e-3);
        assert!(r.p50 <= r.p95 && r.p95 <= r.p99 && r.p99 <= r.max);
        // A report's buckets rebuild the histogram's quantiles.
        let back = Latency::of_reports([&r]);
        assert_eq!(back.report(true).p99, r.p99);
        assert_eq!(back.samples(), 3);
        let json = serde_json::to_string(&l.report(false)).unwrap_or_default();
        assert!(!json.contains("buckets"), "{json}");
    }

    proptest! {
        /// Every quantile is within the stated relative error of the exact
        /// nearest-rank quantile; they are ordered; the maximum is exact.
        #[test]
        fn quantiles_are_within_the_stated_error(
            values in proptest::collection::vec(
                prop_oneof![0..200u64, 0..100_000u64, 0..10_000_000_000u64], 1..400),
            p in 0.001..1.0f64,
        ) {
            let mut h = Histogram::new();
            for &v in &values {
                h.record(v);
            }
            let mut sorted = values.clone();
            sorted.sort_unstable();
            let q = exact(&sorted, p);
            let got = h.quantile(p);
            let err = got.abs_diff(q) as f64;
            prop_assert!(err <= RELATIVE_ERROR * q as f64, "p {} exact {} got {}", p, q, got);
            prop_assert_eq!(h.quantile(1.0), sorted[sorted.len() - 1]);
            prop_assert!(h.quantile(0.5) <= h.quantile(0.95));
            prop_assert!(h.quantile(0.95) <= h.quantile(0.99));
            prop_assert!(h.quantile(0.99) <= h.max());
        }

        /// Merging two histograms is recording both sets, and a report's
        /// buckets rebuild the same quantiles.
        #[test]
        fn merge_is_recording_both(
            a in proptest::collection::vec(0..1_000_000_000u64, 0..100),
            b in proptest::collection::vec(0..1_000_000_000u64, 1..100),
        ) {
            let (mut ha, mut hb, mut hab) = (Histogram::new(), Histogram::new(), Histogram::new());
            for &v in &a { ha.record(v); hab.record(v); }
            for &v in &b { hb.record(v); hab.record(v); }
            ha.merge(&hb);
            prop_assert_eq!(&ha, &hab);
            let mut l = Latency::new();
            for &v in a.iter().chain(&b) { l.record(Some(v as i64)); }
            let rebuilt = Latency::of_reports([&l.report(true)]);
            for p in [0.5, 0.95, 0.99] {
                let (x, y) = (rebuilt.histogram().quantile(p), hab.quantile(p));
                prop_assert!(x.abs_diff(y) as f64 <= 2.0 * RELATIVE_ERROR * y as f64);
            }
        }
    }
}
