//! What a robot does with each message: delays recorded, stale, reordered
//! and garbage ones refused, injected loss and delay.

use super::*;

/// Robot 1 of the fast circle (`extrapolate`), to feed by hand, and the
/// reference.
fn robot_1() -> (Robot, Reference) {
    let s = scenario(EXTRAPOLATE);
    (robot(&s, 1, FaultSpec::default()), reference(&s))
}

/// Every message taken in has its delay recorded (garbage too: the
/// delay is the transport's), unstamped ones counted apart, and the
/// report's latency counts add up to `counters.received`.
#[test]
fn every_received_message_has_its_delay_recorded() {
    let (mut r, reference) = robot_1();
    let mut buf = Vec::new();
    for (k, delay) in [Some(200_000), Some(400_000), None, Some(-3)]
        .into_iter()
        .enumerate()
    {
        reference_message(&mut buf, k as u64, 0.02 * k as f64, &reference);
        r.on_stamped_message(&buf, 0.02 * k as f64, delay);
    }
    r.on_stamped_message(&[0xEC], 0.1, Some(1_000_000));
    let rep = r.report();
    assert_eq!(rep.counters.received, 5);
    let l = &rep.latency;
    assert_eq!((l.count, l.unstamped, l.early), (4, 1, 1));
    assert_eq!(l.count + l.unstamped, rep.counters.received);
    assert!((l.max - 1e-3).abs() < 1e-15);
    assert!((l.p50 - 2e-4).abs() <= 2e-4 * crate::latency::RELATIVE_ERROR);
    assert_eq!(l.buckets.iter().map(|b| b.1).sum::<u64>(), 4);
}

/// Out-of-order, duplicate, stale (old or from the future) and garbage
/// messages are counted and refused; the law keeps the newest accepted
/// sample, advanced by its age.
#[test]
fn stale_reordered_and_garbage_messages_are_counted_and_refused() {
    let (mut r, reference) = robot_1();
    let mut buf = Vec::new();
    reference_message(&mut buf, 0, 0.0, &reference);
    r.on_message(&buf, 0.0);
    assert!(r.is_due(0.0));
    assert_eq!(
        r.tick(0.0).publish.map(|p| p.1.link),
        Some(LinkStatus::Tracking)
    );
    reference_message(&mut buf, 5, 0.1, &reference);
    r.on_message(&buf, 0.1);
    reference_message(&mut buf, 3, 0.06, &reference); // reordered
    r.on_message(&buf, 0.101);
    reference_message(&mut buf, 5, 0.1, &reference); // duplicate
    r.on_message(&buf, 0.102);
    reference_message(&mut buf, 6, -1.5, &reference); // stale: 1.6 s old
    r.on_message(&buf, 0.103);
    reference_message(&mut buf, 7, 2.0, &reference); // stale: from the future
    r.on_message(&buf, 0.104);
    r.on_message(&[0xEC, 1, 1], 0.105); // malformed
    let mut wrong = buf.clone();
    wrong[1] = 9;
    r.on_message(&wrong, 0.106); // wrong version
    let mut state = Vec::new();
    wire::encode_state(
        &mut state,
        Header { source: 9, seq: 0 },
        &RobotState {
            agent: 2,
            link: LinkStatus::Tracking,
            ..RobotState::default()
        },
    );
    r.on_message(&state, 0.107); // a state on the reference key: foreign
    let out = r.tick(0.13);
    let c = *r.counters();
    assert_eq!(
        (
            c.received,
            c.accepted,
            c.reordered,
            c.stale,
            c.malformed,
            c.wrong_version,
            c.foreign
        ),
        (9, 2, 2, 2, 1, 1, 1),
        "{c:?}"
    );
    conserved(&r);
    // The sample of seq 5 (t = 0.1), advanced by 0.03 s.
    let jet = reference.eval(0.1, Order::Two);
    let sample = LeaderSample {
        t: 0.1,
        motion: LeaderMotion::of_jet(&jet),
        speed: jet.speed(),
        turn_rate: jet.turn_rate(),
    };
    let want = predict(&sample, 0.13, 0.5, &r.config().loss);
    let (_, st) = out.publish.unwrap_or_else(|| panic!("published"));
    assert_eq!(st.leader, want.motion);
    assert_eq!(st.link, LinkStatus::Tracking);
}

/// `--loss 0.2`: about a fifth of the messages are dropped, the same ones
/// for the same seed (the same run, bit for bit), and the formation still
/// converges.
#[test]
fn injected_loss_is_seeded_and_the_formation_still_converges() {
    let s = scenario(EXTRAPOLATE);
    let faults = FaultSpec {
        loss: 0.2,
        seed: 7,
        ..FaultSpec::default()
    };
    let run = || {
        let mut w = Fleet::of(&s, &[faults; 2]);
        w.run_until(30.0);
        w.robots().map(Robot::report).collect::<Vec<_>>()
    };
    let (a, b) = (run(), run());
    for (ra, rb) in a.iter().zip(&b) {
        assert_eq!(ra.final_state, rb.final_state);
        assert_eq!(ra.counters, rb.counters);
        let c = ra.counters;
        let rate = c.injected_loss as f64 / c.received as f64;
        // Binomial(~1500 or ~3000, 0.2): σ ≤ 0.011; 3σ.
        assert!((rate - 0.2).abs() < 0.033, "{rate} {c:?}");
        assert_eq!(c.accepted + c.injected_loss, c.received, "{c:?}");
        assert!(ra.final_error < 1e-3, "{ra:?}");
    }
}

/// `--delay 50 ms`: a sample is used only once delivered, 50 ms after it
/// arrived; the robot waits until the first one and then converges on
/// samples advanced by their age.
#[test]
fn injected_delay_holds_samples_back() {
    let s = scenario(EXTRAPOLATE);
    let mut w = Fleet::of(&s, &[delayed(0.05)]);
    w.run_until(0.2);
    let log = w.log(0);
    let first = log
        .iter()
        .find(|p| p.state.link == LinkStatus::Tracking)
        .unwrap_or_else(|| panic!("never tracked"));
    // Synced at 0 on the first arrival; waiting ticks come every 0.1 s,
    // so the first sample (delivered at 0.05) is first used at 0.1.
    assert!((first.state.t - 0.1).abs() < 1e-9, "{first:?}");
    let waiting = log
        .iter()
        .take_while(|p| p.state.link == LinkStatus::Waiting)
        .count();
    assert_eq!(waiting, 1);
    // Messages of the last 50 ms are in flight.
    assert!(
        (2..=3).contains(&w.robot(0).pending()),
        "{}",
        w.robot(0).pending()
    );
    w.run_until(30.0);
    let r = &w.robot(0);
    assert!(r.report().final_error < 1e-3, "{:?}", r.report());
    assert_eq!(r.counters().link_losses, 0);
    conserved(r);
}
