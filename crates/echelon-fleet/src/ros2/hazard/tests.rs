//! The base's safety words: decoded from CDR as a Create 3 and a Jackal
//! send them, refused when wrong, in force by the module's rules.

use super::*;
use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{Header, Time};
use proptest::prelude::*;

fn vector(types: &[u8]) -> Vec<u8> {
    HazardDetectionVector {
        header: Header {
            stamp: Time { sec: 7, nanosec: 0 },
            frame_id: "base_link".to_owned(),
        },
        detections: types
            .iter()
            .map(|&t| HazardDetection {
                header: Header {
                    stamp: Time { sec: 7, nanosec: 0 },
                    frame_id: "bump_front_center".to_owned(),
                },
                r#type: t,
            })
            .collect(),
    }
    .to_cdr()
}

fn hazard_key() -> String {
    topic_key(
        KeyScheme::RmwZenoh,
        0,
        "/bot1/hazard_detection",
        &HAZARD_DETECTION_VECTOR,
    )
}

fn estop_key() -> String {
    topic_key(
        KeyScheme::RmwZenoh,
        0,
        "/bot1/platform/emergency_stop",
        &BOOL,
    )
}

#[test]
fn create3_types_map_to_hazards_and_only_the_dangerous_ones_stop() {
    for t in 0..=255u8 {
        let h = Hazard::of_create3(t);
        assert_eq!(h.is_some(), t <= 5, "{t}");
        if let Some(h) = h {
            assert_eq!(Hazard::from_name(h.name()), Some(h));
            assert_eq!(h.stops(), (1..=4).contains(&t), "{h:?}");
        }
    }
    assert!(Hazard::EmergencyStop.stops());
    let all: HazardSet = Hazard::ALL.into_iter().collect();
    assert_eq!(
        all.stopping().names(),
        "BUMP+CLIFF+STALL+WHEEL_DROP+EMERGENCY_STOP"
    );
    let json = serde_json::to_string(&all.stopping()).unwrap_or_default();
    assert_eq!(
        serde_json::from_str::<HazardSet>(&json).ok(),
        Some(all.stopping())
    );
}

#[test]
fn a_bump_is_in_force_until_a_vector_without_it_or_silence() {
    let mut b = BaseSafety::new(KeyScheme::RmwZenoh);
    let key = hazard_key();
    assert_eq!(b.on_hazards(&key, &vector(&[]), 0.0), Ok(HazardSet::EMPTY));
    assert!(b.update(0.0).is_empty());
    // A bump and an obstacle close by: the bump stops, the proximity is logged.
    let got = b.on_hazards(&key, &vector(&[1, 5]), 1.0);
    assert_eq!(
        got.map(HazardSet::names),
        Ok("BUMP+OBJECT_PROXIMITY".to_owned())
    );
    assert_eq!(b.update(1.0).names(), "BUMP");
    assert_eq!(b.in_force(1.0 + HAZARD_CLEAR_AFTER).names(), "BUMP");
    // Cleared by an empty vector…
    let _ = b.on_hazards(&key, &vector(&[]), 1.5);
    assert!(b.update(1.5).is_empty());
    // …or by silence past HAZARD_CLEAR_AFTER.
    let _ = b.on_hazards(&key, &vector(&[2]), 2.0);
    assert_eq!(b.update(2.5).names(), "CLIFF");
    assert!(b.update(2.0 + HAZARD_CLEAR_AFTER + 1e-9).is_empty());
    let r = b.report();
    assert_eq!(
        r.events,
        vec![
            HazardEvent {
                hazard: Hazard::Bump,
                at: 1.0,
                cleared: Some(1.5)
            },
            HazardEvent {
                hazard: Hazard::Cliff,
                at: 2.0,
                cleared: Some(2.0 + HAZARD_CLEAR_AFTER + 1e-9)
            },
        ]
    );
    assert_eq!(
        (
            r.counts.hazard_received,
            r.counts.object_proximity,
            r.counts.onsets
        ),
        (4, 1, 2)
    );
    // The latest onset, with its clearing, in the report and the stats.
    assert_eq!(r.last, r.events.last().copied());
    assert_eq!(r.stats().last, r.last);
}

/// Past [`MAX_EVENTS`] onsets the report keeps the first ones, and the
/// latest onset still: `fleet status` shows it.
#[test]
fn the_latest_onset_is_kept_past_the_events_cap() {
    let mut b = BaseSafety::new(KeyScheme::RmwZenoh);
    let key = hazard_key();
    let n = MAX_EVENTS + 10;
    for i in 0..n {
        let t = i as f64;
        let _ = b.on_hazards(&key, &vector(&[1]), t);
        let _ = b.on_hazards(&key, &vector(&[]), t + 0.5);
    }
    let _ = b.on_hazards(&key, &vector(&[2]), n as f64);
    let r = b.report();
    assert_eq!(r.events.len(), MAX_EVENTS);
    assert_eq!(r.counts.onsets, n as u64 + 1);
    assert_eq!(
        r.stats().last,
        Some(HazardEvent {
            hazard: Hazard::Cliff,
            at: n as f64,
            cleared: None
        })
    );
    let _ = b.on_hazards(&key, &vector(&[]), n as f64 + 0.25);
    assert_eq!(
        b.report().last.and_then(|e| e.cleared),
        Some(n as f64 + 0.25)
    );
}

#[test]
fn an_estop_is_latched_until_false() {
    let mut b = BaseSafety::new(KeyScheme::RmwZenoh);
    let key = estop_key();
    assert_eq!(
        b.on_estop(&key, &Bool { data: true }.to_cdr(), 0.0),
        Ok(true)
    );
    // Silence never clears an e-stop.
    assert_eq!(b.update(100.0).names(), "EMERGENCY_STOP");
    assert_eq!(
        b.on_estop(&key, &Bool { data: false }.to_cdr(), 101.0),
        Ok(false)
    );
    assert!(b.update(101.0).is_empty());
    // A byte that is no bool is refused and changes nothing.
    let _ = b.on_estop(&key, &Bool { data: true }.to_cdr(), 102.0);
    let mut bad = Bool { data: false }.to_cdr();
    bad[4] = 2;
    assert!(b.on_estop(&key, &bad, 103.0).is_err());
    assert_eq!(b.update(103.0).names(), "EMERGENCY_STOP");
    assert_eq!(b.counts().estop_refused, 1);
}

#[test]
fn wrong_types_and_garbage_are_refused_and_clear_nothing() {
    let mut b = BaseSafety::new(KeyScheme::RmwZenoh);
    let key = hazard_key();
    let _ = b.on_hazards(&key, &vector(&[4]), 0.0);
    let wrong = topic_key(KeyScheme::RmwZenoh, 0, "/bot1/hazard_detection", &BOOL);
    assert!(matches!(
        b.on_hazards(&wrong, &vector(&[]), 0.1),
        Err(SampleRefusal::WrongType(_))
    ));
    assert!(b.on_hazards(&key, &vector(&[9]), 0.2).is_err());
    assert!(
        b.on_hazards(&key, b"\x00\x01\x00\x00\xff\xff\xff\xff", 0.3)
            .is_err()
    );
    assert!(b.on_hazards(&key, &[], 0.4).is_err());
    assert_eq!(b.update(0.5).names(), "WHEEL_DROP");
    assert_eq!(b.counts().hazard_refused, 4);
}

proptest! {
    /// Over any sequence of vectors, e-stops, garbage and times: what is in
    /// force is exactly the module's rule, every onset is an event, every
    /// event is closed exactly when its hazard left, and nothing panics.
    #[test]
    fn in_force_follows_the_rule(
        ops in proptest::collection::vec(
            (0u8..4, proptest::collection::vec(0u8..7, 0..4), 0.0f64..1.5),
            1..60,
        ),
    ) {
        let mut b = BaseSafety::new(KeyScheme::RmwZenoh);
        let (hk, ek) = (hazard_key(), estop_key());
        let mut t = 0.0;
        let mut reported = HazardSet::EMPTY;
        let mut reported_at = f64::NEG_INFINITY;
        let mut estop = false;
        for (kind, types, dt) in ops {
            t += dt;
            match kind {
                0 => {
                    let valid = types.iter().all(|&x| x <= 5);
                    let r = b.on_hazards(&hk, &vector(&types), t);
                    prop_assert_eq!(r.is_ok(), valid);
                    if valid {
                        reported = types.iter().filter_map(|&x| Hazard::of_create3(x)).collect::<HazardSet>().stopping();
                        reported_at = t;
                    }
                }
                1 => {
                    let on = types.len() % 2 == 1;
                    prop_assert_eq!(b.on_estop(&ek, &Bool { data: on }.to_cdr(), t), Ok(on));
                    estop = on;
                }
                2 => {
                    let mut garbage = vector(&types);
                    let cut = garbage.len() / 2;
                    garbage.truncate(cut);
                    let _ = b.on_hazards(&hk, &garbage, t);
                }
                _ => {}
            }
            let mut expected = if t - reported_at <= HAZARD_CLEAR_AFTER { reported } else { HazardSet::EMPTY };
            if estop {
                expected = expected.with(Hazard::EmergencyStop);
            }
            prop_assert_eq!(b.update(t), expected);
            let r = b.report();
            for h in Hazard::ALL {
                let open = r.events.iter().filter(|e| e.hazard == h && e.cleared.is_none()).count();
                prop_assert_eq!(open, usize::from(expected.contains(h)), "{:?}", h);
            }
            prop_assert_eq!(r.counts.onsets as usize, r.events.len());
            // The latest onset, cleared or not, as the stats carry it.
            prop_assert_eq!(r.last, r.events.last().copied());
            prop_assert_eq!(r.stats().last, r.last);
        }
    }
}
