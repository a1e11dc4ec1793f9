//! One robot's ROS 2 side as `fleet doctor` sees it, never sending to it:
//! its odometry heard (rate against the scenario's `odom_rate`, frames,
//! and under which topic), its `cmd_vel` reader and safety topics in its
//! graph (liveliness tokens), and its fixes (rate, age).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use zenoh::Wait;

use echelon::scenario::Ros2Link;
use echelon_ros2::graph::{Direction, GraphEndpoint};
use echelon_ros2::keys::topic_key_any_type;
use echelon_ros2::msgs::{Header, ODOMETRY, Odometry, RosMessage};
use echelon_ros2::names::KeyScheme;

use super::report::{Row, Status};
use crate::FleetError;
use crate::ros2::graph;

/// Odometry slower than this share of the scenario's `odom_rate` fails.
pub const ODOM_FAIL_BELOW: f64 = 0.8;
/// Odometry slower than this share of `odom_rate` warns.
pub const ODOM_WARN_BELOW: f64 = 0.95;
/// Odometry faster than this multiple of `odom_rate` warns (two
/// publishers on one topic, or another rate than the scenario says).
pub const ODOM_WARN_ABOVE: f64 = 1.25;

/// What arrived on one topic.
#[derive(Debug, Default, Clone)]
struct Heard {
    count: u32,
    malformed: u32,
    first: Option<Instant>,
    last: Option<Instant>,
    /// The longest gap between two arrivals, s.
    longest_gap: f64,
    /// Odometry: its `(frame_id, child_frame_id)`.
    frames: Option<(String, String)>,
    /// Fixes: the newest one's age by its stamp when it arrived, s
    /// (`None`: stamped zero, "now").
    age: Option<f64>,
}

impl Heard {
    fn arrived(&mut self) {
        let now = Instant::now();
        if let Some(last) = self.last {
            self.longest_gap = self.longest_gap.max((now - last).as_secs_f64());
        }
        self.first.get_or_insert(now);
        self.last = Some(now);
        self.count += 1;
    }

    /// Arrivals per second between the first and the last.
    fn rate(&self) -> Option<f64> {
        let span = (self.last? - self.first?).as_secs_f64();
        (self.count >= 2 && span > 0.0).then(|| f64::from(self.count - 1) / span)
    }
}

type Shared<T> = Arc<Mutex<T>>;

/// A robot's ROS 2 side being listened to.
pub(super) struct Watch {
    link: Ros2Link,
    started: Instant,
    /// The scenario's odometry topic.
    odom: Shared<Heard>,
    /// Odometry heard on other topics, by topic.
    elsewhere: Shared<BTreeMap<String, Heard>>,
    /// Its fixes, when it takes some: what arrived, and how often they
    /// should come (period, timeout), s.
    fixes: Option<(Shared<Heard>, f64, f64)>,
    /// Its graph when listening started.
    graph: Vec<GraphEndpoint>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

/// The ROS name of the topic a data key of `scheme` carries (`None`: not
/// such a key).
fn topic_of_key(scheme: KeyScheme, key: &str) -> Option<String> {
    match scheme {
        KeyScheme::Bridge => Some(format!("/{key}")),
        KeyScheme::RmwZenoh | KeyScheme::RmwZenohHumble => {
            let chunks: Vec<&str> = key.split('/').collect();
            (chunks.len() >= 4).then(|| format!("/{}", chunks[1..chunks.len() - 2].join("/")))
        }
    }
}

/// Counts an odometry sample into `h`.
fn count_odometry(h: &mut Heard, payload: &[u8]) {
    match Odometry::from_cdr_finite(payload) {
        Ok(m) => {
            h.arrived();
            h.frames = Some((m.header.frame_id, m.child_frame_id));
        }
        Err(_) => h.malformed += 1,
    }
}

impl Watch {
    /// Reads `link`'s robot graph on `session` and starts listening to its
    /// odometry (on the scenario's topic, and on every other odometry topic
    /// of its domain) and its fixes, `fix_timing` their period and the
    /// timeout after which they are missed, s.
    pub(super) fn start(
        session: &zenoh::Session,
        link: &Ros2Link,
        fix_timing: Option<(f64, f64)>,
    ) -> Result<Watch, FleetError> {
        let graph = graph::seen(session, link.domain_id)?;
        let (scheme, domain) = (link.key_scheme, link.domain_id);
        let mut subscribers = Vec::new();
        let mut subscribe = |key: String, cb: Box<dyn Fn(&zenoh::sample::Sample) + Send + Sync>| {
            session
                .declare_subscriber(&key)
                .callback(move |s| cb(&s))
                .wait()
                .map(|s| subscribers.push(s))
                .map_err(|e| FleetError::Zenoh(format!("subscribing to {key}: {e}")))
        };
        let odom: Shared<Heard> = Arc::default();
        let sink = odom.clone();
        subscribe(
            topic_key_any_type(scheme, domain, &link.odom),
            Box::new(move |s| {
                if let Ok(mut h) = sink.lock() {
                    count_odometry(&mut h, &s.payload().to_bytes());
                }
            }),
        )?;
        // Odometry elsewhere: any key of the type (rmw_zenoh's keys carry
        // it), and every odometry publisher the graph announces.
        let elsewhere: Shared<BTreeMap<String, Heard>> = Arc::default();
        let mut other_keys: Vec<String> = graph
            .iter()
            .filter(|e| e.direction == Direction::Publisher && e.type_name == ODOMETRY.name)
            .filter(|e| e.topic != link.odom)
            .map(|e| topic_key_any_type(scheme, domain, &e.topic))
            .collect();
        if scheme != KeyScheme::Bridge {
            other_keys = vec![format!("{domain}/**/{}/*", ODOMETRY.dds_name())];
        }
        let own_topic = link.odom.clone();
        for key in other_keys {
            let sink = elsewhere.clone();
            let own_topic = own_topic.clone();
            // Best effort: an access control may refuse a wildcard.
            let _ = subscribe(
                key,
                Box::new(move |s| {
                    let Some(topic) = topic_of_key(scheme, s.key_expr().as_str()) else {
                        return;
                    };
                    if topic == own_topic {
                        return;
                    }
                    if let Ok(mut all) = sink.lock() {
                        count_odometry(all.entry(topic).or_default(), &s.payload().to_bytes());
                    }
                }),
            );
        }
        let fixes = match (&link.fixes, fix_timing) {
            (Some(source), Some((period, timeout))) => {
                let heard: Shared<Heard> = Arc::default();
                let sink = heard.clone();
                subscribe(
                    topic_key_any_type(scheme, domain, &source.topic),
                    Box::new(move |s| {
                        let received = crate::unix_nanos() as i64;
                        let Ok(mut h) = sink.lock() else {
                            return;
                        };
                        // Both fix types start with their header.
                        match Header::from_cdr(&s.payload().to_bytes()) {
                            Ok(header) => {
                                h.arrived();
                                let stamp = header.stamp.to_nanos();
                                h.age = (stamp != 0).then(|| (received - stamp) as f64 * 1e-9);
                            }
                            Err(_) => h.malformed += 1,
                        }
                    }),
                )?;
                Some((heard, period, timeout))
            }
            _ => None,
        };
        Ok(Watch {
            link: link.clone(),
            started: Instant::now(),
            odom,
            elsewhere,
            fixes,
            graph,
            _subscribers: subscribers,
        })
    }

    /// When listening started.
    pub(super) fn started(&self) -> Instant {
        self.started
    }

    /// The rows of `subject` from what was heard so far.
    pub(super) fn rows(&self, subject: &str) -> Vec<Row> {
        let mut rows = vec![self.odometry_row(subject)];
        let listened = self.started.elapsed().as_secs_f64();
        for e in graph::expected(&self.link) {
            if e.role == "odom" {
                continue;
            }
            let check = match e.direction {
                Direction::Subscription => format!("{} reader", e.role),
                Direction::Publisher => format!("{} publisher", e.role),
            };
            let row = Row::new(subject, &check, Status::Pass, e.topic, "");
            rows.push(
                match echelon_ros2::graph::check(&self.graph, &self.link.namespace, &[e]) {
                    Ok(()) => Row {
                        detail: format!("{} in its ROS 2 graph", e.ty.name),
                        ..row
                    },
                    Err(problem) => Row {
                        status: Status::Fail,
                        detail: format!("{problem} (from its graph's liveliness tokens)"),
                        ..row
                    },
                },
            );
        }
        if self.link.driven {
            rows.push(Row::new(
                subject,
                "cmd_vel reader",
                Status::Info,
                &self.link.cmd_vel,
                "driven by someone else: echelon sends it no cmd_vel",
            ));
        }
        if let Some((heard, period, timeout)) = &self.fixes {
            rows.push(fix_row(
                subject, &self.link, heard, *period, *timeout, listened,
            ));
        }
        rows
    }

    fn odometry_row(&self, subject: &str) -> Row {
        let listened = self.started.elapsed().as_secs_f64();
        let want = self.link.odom_rate;
        let topic = &self.link.odom;
        let heard = self.odom.lock().map(|h| h.clone()).unwrap_or_default();
        let row = Row::new(subject, "odometry", Status::Fail, "none", "");
        if heard.count == 0 {
            let elsewhere = self.elsewhere.lock().map(|e| e.clone()).unwrap_or_default();
            let heard: Vec<&String> = elsewhere
                .iter()
                .filter(|(_, h)| h.count > 0)
                .map(|(t, _)| t)
                .collect();
            let relative = topic
                .strip_prefix(self.link.namespace.trim_end_matches('/'))
                .unwrap_or(topic);
            let same_name: Vec<&str> = heard
                .iter()
                .filter(|t| t.ends_with(relative))
                .map(|t| t.as_str())
                .collect();
            let detail = if !same_name.is_empty() {
                format!(
                    "wrong namespace: heard {}, the scenario says {topic} (namespace {}): set the agent's ros2.namespace",
                    same_name.join(", "),
                    self.link.namespace,
                )
            } else if heard.is_empty() {
                format!(
                    "no odometry on {topic} within {listened:.1} s, nor on any other topic: is the robot's driver running, in domain {}?",
                    self.link.domain_id
                )
            } else {
                let others: Vec<&str> = heard.iter().map(|t| t.as_str()).collect();
                format!(
                    "no odometry on {topic} within {listened:.1} s; heard on {} instead: is ros2.odom the right topic?",
                    others.join(", ")
                )
            };
            let malformed = match heard_malformed(&self.odom) {
                0 => detail,
                n => format!("{detail}; {n} samples on {topic} were not nav_msgs/msg/Odometry"),
            };
            return Row {
                detail: malformed,
                ..row
            };
        }
        let (frame, child) = heard.frames.clone().unwrap_or_default();
        if frame != self.link.odom_frame || child != self.link.base_frame {
            return Row {
                value: format!("{frame} → {child}"),
                detail: format!(
                    "odometry in frames {frame} → {child}, the scenario says {} → {} (odom_frame, base_frame): the robot would refuse every sample",
                    self.link.odom_frame, self.link.base_frame
                ),
                ..row
            };
        }
        let Some(rate) = heard.rate() else {
            return Row {
                value: format!("{} sample", heard.count),
                detail: format!(
                    "one sample on {topic} in {listened:.1} s, the scenario says {want} Hz"
                ),
                ..row
            };
        };
        let status = if rate < ODOM_FAIL_BELOW * want {
            Status::Fail
        } else if rate < ODOM_WARN_BELOW * want || rate > ODOM_WARN_ABOVE * want {
            Status::Warn
        } else {
            Status::Pass
        };
        let verdict = match status {
            Status::Fail => "too slow: check the driver's publish rate and the link",
            Status::Warn if rate > want => "faster than the scenario says: two publishers?",
            Status::Warn => "slower than the scenario says",
            _ => "as the scenario says",
        };
        Row {
            status,
            value: format!("{rate:.1} Hz"),
            detail: format!(
                "{topic}: {} samples in {listened:.1} s, longest gap {:.0} ms; the scenario says {want} Hz (ros2.odom_rate): {verdict}",
                heard.count,
                heard.longest_gap * 1e3
            ),
            ..row
        }
    }
}

fn heard_malformed(h: &Shared<Heard>) -> u32 {
    h.lock().map_or(0, |h| h.malformed)
}

/// The fixes' row: none is a failure; slower than `timeout` apart, or
/// older than it by their stamps, a warning.
fn fix_row(
    subject: &str,
    link: &Ros2Link,
    heard: &Shared<Heard>,
    period: f64,
    timeout: f64,
    listened: f64,
) -> Row {
    let topic = link.fixes.as_ref().map_or("", |f| f.topic.as_str());
    let h = heard.lock().map(|h| h.clone()).unwrap_or_default();
    let row = Row::new(subject, "fixes", Status::Fail, "none", "");
    if h.count == 0 {
        return Row {
            detail: format!(
                "no fix on {topic} within {listened:.1} s{}: is the motion capture or localiser publishing in this robot's ROS graph?",
                match h.malformed {
                    0 => String::new(),
                    n => format!(" ({n} unreadable)"),
                }
            ),
            ..row
        };
    }
    let age = h.age.map_or_else(
        || "stamped now".to_owned(),
        |a| format!("age {:.0} ms", a * 1e3),
    );
    let rate = h
        .rate()
        .map_or_else(|| "1 fix".to_owned(), |r| format!("{r:.1} Hz"));
    let late = h.longest_gap > timeout || h.age.is_some_and(|a| a.abs() > timeout);
    Row {
        status: if late { Status::Warn } else { Status::Pass },
        value: format!("{rate}, {age}"),
        detail: format!(
            "{topic}: {} fixes, longest gap {:.0} ms; expected every {:.0} ms, missed after {:.0} ms{}",
            h.count,
            h.longest_gap * 1e3,
            period * 1e3,
            timeout * 1e3,
            if late {
                ": late (a slow source, or clocks apart: the age is by the fix's stamp)"
            } else {
                ""
            }
        ),
        ..row
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_give_back_their_topics() {
        let key = topic_key_any_type(KeyScheme::RmwZenoh, 3, "/x/robot1/odom");
        let concrete = key.replace('*', "T");
        assert_eq!(
            topic_of_key(KeyScheme::RmwZenoh, &concrete).as_deref(),
            Some("/x/robot1/odom")
        );
        assert_eq!(
            topic_of_key(KeyScheme::Bridge, "tb4/odom").as_deref(),
            Some("/tb4/odom")
        );
        assert_eq!(topic_of_key(KeyScheme::RmwZenoh, "0/odom"), None);
    }

    #[test]
    fn rates_count_intervals() {
        let mut h = Heard::default();
        assert_eq!(h.rate(), None);
        h.arrived();
        assert_eq!(h.rate(), None);
        std::thread::sleep(std::time::Duration::from_millis(20));
        h.arrived();
        std::thread::sleep(std::time::Duration::from_millis(20));
        h.arrived();
        let r = h.rate().unwrap_or(0.0);
        assert!(r > 10.0 && r <= 50.0, "{r}");
        assert!(h.longest_gap >= 0.02);
    }
}
